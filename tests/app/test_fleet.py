"""``jaxdse fleet``: a PSS/E case and its recordings -> fleet.json, fleet.csv and the HTML report."""

import dataclasses
import json
from html.parser import HTMLParser
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import jaxdse as jd
from jaxdse._app.cli import build_parser, main
from jaxdse._app.fleet import load_fleet, run_fleet

ROOT = Path(__file__).resolve().parents[2]
SHARED_DATA = ROOT.parent / "shared" / "data"
BENCH = ROOT / "experiments" / "andes_bench"
OSL = ROOT / "experiments" / "naspi_osl_case1" / "fleet.toml"
UNIT_KEYS = {"name", "H_s", "H_ci95", "H_reference_s", "verdict", "reasons", "D", "interval",
             "playback_smape_percent", "governor_models", "data_quality", "window_errors", "criteria"}


class Links(HTMLParser):
    """The href and src attributes of a page (and a parse of the whole page on the way)."""

    def __init__(self):
        super().__init__()
        self.refs = []

    def handle_starttag(self, tag, attrs):
        self.refs += [v for k, v in attrs if k in ("href", "src")]


def links(path: Path) -> list[str]:
    parser = Links()
    parser.feed(path.read_text())
    parser.close()
    return parser.refs


@pytest.fixture(scope="module")
def ieee14(tmp_path_factory):
    """The ANDES ieee14 line trip as a fleet, run once (8 bootstrap draws instead of 32: time)."""
    out = tmp_path_factory.mktemp("fleet")
    fl = load_fleet(BENCH / "fleet_ieee14.toml")
    doc = run_fleet(dataclasses.replace(fl, identify=jd.IdentifySettings(bootstrap_draws=8)), out)
    return 0, out, json.loads((out / "fleet.json").read_text()) | {"returned": doc}


def test_fleet_json_and_report(ieee14):
    rc, out, doc = ieee14
    assert rc == 0
    names = [u["name"] for u in doc["units"]]
    assert names == ["B1_G1", "B2_G1", "B3_G1", "B6_G1", "B8_G1"]
    truth = {"B1_G1": 4.0, "B2_G1": 6.5, "B3_G1": 5.0, "B6_G1": 5.0, "B8_G1": 5.0}
    for u in doc["units"]:
        assert UNIT_KEYS <= set(u)
        assert u["H_reference_s"] == pytest.approx(truth[u["name"]])
        assert len(u["H_ci95"]) == 2 and u["H_ci95"][0] <= u["H_s"] <= u["H_ci95"][1]
        assert u["verdict"] in jd.VERDICTS and u["governor_models"] == ["TGOV1"]
        assert abs(u["H_error_percent"]) < 25.0
    assert doc["case"]["dyr_models_not_used"] == ["ESST3A", "EXST1"]
    assert all(i["sha256"] for i in doc["inputs"])
    rows = (out / "fleet.csv").read_text().splitlines()
    assert len(rows) == 6 and rows[0].startswith("name,bus,s_mva")
    refs = links(out / "report.html")
    assert "overview.png" in refs and (out / "overview.png").stat().st_size > 0
    for name in names:
        assert f"units/{name}.html" in refs
        page = out / "units" / f"{name}.html"
        assert f"{name}.png" in links(page) and (out / "units" / f"{name}.png").stat().st_size > 0
        assert "../report.html" in links(page)


def test_missing_dyr_exits_2_with_one_line(tmp_path, capsys):
    text = (BENCH / "fleet_ieee14.toml").read_text().replace("data/ieee14/ieee14.dyr", "nowhere.dyr")
    text = text.replace('"data/', f'"{BENCH}/data/')
    cfg = tmp_path / "fleet.toml"
    cfg.write_text(text)
    assert main(["fleet", str(cfg), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nowhere.dyr" in err[0] and "does not exist" in err[0]
    assert not (tmp_path / "out").exists()


def test_explicit_units_and_help(tmp_path):
    text = (BENCH / "fleet_ieee14.toml").read_text().replace('"data/', f'"{BENCH}/data/')
    text = text[:text.index("[channels]")] + """
[[unit]]
name = "two"
bus = 2
columns = {time = "time_s", v_mag = "B2_G1/VM", v_ang = "B2_G1/VA", i_mag = "B2_G1/IM", i_ang = "B2_G1/IA"}
"""
    cfg = tmp_path / "fleet.toml"
    cfg.write_text(text)
    fl = load_fleet(cfg)
    assert [p.name for p in fl.plants] == ["two"]
    assert float(fl.plants[0].run.plant.machine.s_rated_mva) == 100.0
    sub = build_parser()._subparsers._group_actions[0].choices["fleet"]
    text = sub.format_help()
    for word in ("[case]", "[channels]", "[[unit]]", "[criteria]", "report.html", "fleet.json",
                 "units/<name>.html", "Exit status"):
        assert word in text


def test_weighted_governor_sums_units():
    g = jd.WeightedGovernor((jd.TGOV1(), jd.GAST(), jd.HYGOV()), [0.5, 0.3, 0.0])
    x = g.steady_state(0.7, 0.0)
    assert float(g.torque(x, 0.0)) == pytest.approx(0.7)
    assert np.allclose(g.vector_field(x, 0.0, 0.7), 0.0)
    ref = g.reference_from_steady(0.7, 1e-3)
    x = g.steady_state(ref, 1e-3)
    assert float(g.torque(x, 1e-3)) == pytest.approx(0.7, abs=1e-9)
    assert np.allclose(g.vector_field(x, 1e-3, ref), 0.0, atol=1e-12)
    # one step of speed: the sum of the units' own responses, weighted
    dw = 2e-3
    units = [jd.TGOV1(), jd.GAST()]
    own = [u.vector_field(u.steady_state(u.reference_from_steady(0.7, 0.0), 0.0), dw,
                          u.reference_from_steady(0.7, 0.0)) for u in units]
    d = g.vector_field(g.steady_state(0.7, 0.0), dw, 0.7)
    assert np.allclose(d[:5], jnp.concatenate(own))
    with pytest.raises(ValueError, match="sum to <= 1"):
        jd.WeightedGovernor((jd.TGOV1(), jd.GAST()), [0.7, 0.6])


@pytest.mark.skipif(not (SHARED_DATA / "naspi_osl_2021").exists(), reason="shared NASPI data absent")
def test_osl_case1_plants_from_the_case():
    fl = load_fleet(OSL)
    assert len(fl.plants) == 22
    by = {p.name: p for p in fl.plants}
    hoover = by["1331_hoover"]
    assert {m.governor for m in hoover.members} == {"GAST", "HYGOV"}
    assert [type(g).__name__ for g in hoover.run.plant.governor.governors] == ["TGOV1", "GAST", "HYGOV"]
    w = np.asarray(hoover.run.plant.governor.weights)
    assert w[0] == 0.0 and w.sum() == pytest.approx(1.0)
    s = sum(m.mbase_mva for m in hoover.members)
    assert hoover.run.h_reference_s == pytest.approx(sum(m.h_s * m.mbase_mva for m in hoover.members) / s)
    assert hoover.run.measurement.columns["v_mag"].startswith("BusVolMag/1331|")
    assert {p.run.measurement.current_direction for p in fl.plants} <= {"out_of_plant", "into_plant"}
