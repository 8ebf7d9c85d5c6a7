"""The TOML schema (``_io/schema.py``) shared by run configs and fleet files: typed [identify]
options, [measurement]'s CSV keys, the governor registry, and the layering (parsing only;
nothing here runs the pipeline)."""

import ast
import dataclasses
import tomllib
from pathlib import Path
from typing import Literal

import pytest

import jaxdse as jd
from jaxdse._io.config import parse_config
from jaxdse._io.psse import GOVERNOR_FIELDS, GOVERNOR_PARAMETERS
from jaxdse._io.schema import field_types, typed_value
from jaxdse._models.governors import GOVERNORS

ROOT = Path(__file__).resolve().parents[2]
BASE = """
plant_defaults = "paper"

[measurement]
file = "pmu.csv"
v_base_kv = 400.0
columns = {time = "t", v_mag = "VM", v_ang = "VA", i_mag = "IM", i_ang = "IA"}
"""


def parse(tmp_path, extra: str = ""):
    return parse_config(tomllib.loads(BASE + extra), tmp_path / "c.toml")


def refused(tmp_path, extra: str) -> str:
    with pytest.raises(jd.InputError) as err:
        parse(tmp_path, extra)
    msg = str(err.value)
    assert "\n" not in msg
    return msg


def toml_value(v) -> str:
    """A Python default written as TOML."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, tuple):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, str):
        return f'"{v}"'
    return repr(v)


def test_identify_options_typed_from_the_fields(tmp_path):
    cfg = parse(tmp_path, "[identify]\nbootstrap_draws = 8\nhuber_k = 2\n")
    assert cfg.identify.bootstrap_draws == 8 and type(cfg.identify.bootstrap_draws) is int
    assert cfg.identify.huber_k == 2.0 and type(cfg.identify.huber_k) is float
    cfg = parse(tmp_path, "[identify]\nnoise_interval = \"sandwich\"\nbootstrap_draws = 0\n"
                          "output_error = true\nspread_scales = [0.25, 4]\nmodel_error = 0\n")
    assert cfg.identify.noise_interval == "sandwich"
    assert cfg.identify.bootstrap_draws == 0 and cfg.identify.output_error is True
    assert cfg.identify.spread_scales == (0.25, 4.0) and cfg.identify.model_error == 0.0
    assert parse(tmp_path, "[identify]\nspread_scales = []\n").identify.spread_scales == ()
    assert parse(tmp_path, "[identify]\nenabled = false\n").identify is None


@pytest.mark.parametrize("cls", [jd.IdentifySettings, jd.VerdictSettings])
def test_every_identify_field_can_be_set(tmp_path, cls):
    """Generic over the fields: each one, written as its own default, reads back equal."""
    defaults = cls()
    for f in dataclasses.fields(cls):
        got = parse(tmp_path, f"[identify]\n{f.name} = {toml_value(getattr(defaults, f.name))}\n")
        value = getattr(got.identify if cls is jd.IdentifySettings else got.verdict, f.name)
        assert value == getattr(defaults, f.name) and type(value) is type(getattr(defaults, f.name)), f.name


@pytest.mark.parametrize("extra, words", [
    ("bootstrap_draws = 8.5", "must be an integer >= 0, got 8.5"),
    ("bootstrap_draws = -1", "must be an integer >= 0"),
    ("bootstrap_draws = true", "must be an integer"),
    ("output_error = 1", "must be true or false, got 1"),
    ("spread_scales = 2.0", "must be a list of numbers"),
    ("spread_scales = [0.5, \"x\"]", "must be a number"),
    ("huber_k = \"1.3\"", "must be a number"),
    ("identified_ci = -0.1", "must be >= 0"),
    ("enabled = 1", "must be true or false"),
    ("bootstrap_drawz = 8", "did you mean 'bootstrap_draws'"),
])
def test_bad_identify_option_names_the_key(tmp_path, extra, words):
    msg = refused(tmp_path, f"[identify]\n{extra}\n")
    key = extra.split(" =")[0]
    assert f"key 'identify.{key}" in msg and words in msg, msg


def test_typed_value_literal_enum_and_optional():
    assert typed_value("f", Literal["trajectories", "final"], "final", "k") == "final"
    with pytest.raises(jd.InputError, match="'trajectories', 'final'"):
        typed_value("f", Literal["trajectories", "final"], "all", "k")
    assert typed_value("f", bool | None, True, "k") is True
    assert typed_value("f", float | None, 3, "k") == 3.0
    assert field_types(jd.Settings)["keep"] == Literal["trajectories", "final"]


def test_settings_and_tune_sections(tmp_path):
    cfg = parse(tmp_path, "[settings]\nderivative_half_width = 3\nqss_window_s = 10\n")
    assert cfg.settings.derivative_half_width == 3 and cfg.settings.qss_window_s == 10.0
    assert "key 'settings.derivative_half_width'" in refused(
        tmp_path, "[settings]\nderivative_half_width = 0\n")
    assert "key 'settings.min_hold_s'" in refused(tmp_path, "[settings]\nmin_hold_s = -1\n")
    cfg = parse(tmp_path, "[tune]\nweights = {x2 = 2, band = 0.02}\n")
    assert cfg.tune["weights"] == jd.LossWeights(x2=2.0, band=0.02)
    assert "key 'tune.weights.x3'" in refused(tmp_path, "[tune]\nweights = {x3 = 2}\n")
    assert "key 'sweep.draws'" in refused(tmp_path, "[sweep]\ndraws = 0\n")
    assert "key 'output.figures'" in refused(tmp_path, "[output]\nfigures = \"no\"\n")


def test_measurement_holds_csv_options(tmp_path):
    spec = parse(tmp_path, """
delimiter = ";"
decimal = ","
na_values = ["---"]
skip_rows = 2
units_row = true
""").generators[0].measurement   # keys of [measurement], the last table of BASE
    assert spec.csv_options == jd.CsvOptions(delimiter=";", decimal=",", na_values=("---",),
                                          skip_rows=2, units_row=True)
    assert parse(tmp_path).generators[0].measurement.csv_options == jd.CsvOptions()
    assert "csv_options" not in {f.name for f in dataclasses.fields(jd.CsvOptions)}
    for extra, key in (("skip_rows = -1", "skip_rows"), ("units_row = 1", "units_row"),
                       ("decimal = \";\"", "decimal"), ("csv_options = 1", "csv_options"),
                       ("delimiter = \"\"", "delimiter")):
        text = BASE.replace('v_base_kv = 400.0', f'v_base_kv = 400.0\n{extra}')
        with pytest.raises(jd.InputError, match=f"key 'measurement.{key}'"):
            parse_config(tomllib.loads(text), tmp_path / "c.toml")


def test_one_governor_registry(tmp_path):
    cfg = parse(tmp_path, "[governor]\nmodel = \"GAST\"\nr_pu = 0.04\n")
    assert isinstance(cfg.generators[0].plant.governor, jd.GAST)
    msg = refused(tmp_path, "[governor]\nmodel = \"IEEEG2\"\n")
    assert "key 'governor.model'" in msg and ", ".join(GOVERNORS) in msg
    assert set(GOVERNORS) == set(GOVERNOR_FIELDS) == set(GOVERNOR_PARAMETERS)
    for model, names in GOVERNOR_PARAMETERS.items():
        fields = {f.name for f in dataclasses.fields(GOVERNORS[model])}
        assert set(names) <= fields and set(names.values()) <= set(GOVERNOR_FIELDS[model]), model


def test_run_config_refuses_a_fleet_file(tmp_path):
    text = (ROOT / "experiments" / "andes_bench" / "fleet_ieee14.toml").read_text()
    with pytest.raises(jd.InputError, match="fleet file.*use `jaxdse fleet"):
        parse_config(tomllib.loads(text), tmp_path / "fleet.toml")


def imports(path: Path) -> set[str]:
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            out.add("." * node.level + (node.module or ""))
            out.update(f"{'.' * node.level}{node.module or ''}:{a.name}" for a in node.names)
    return out


def test_the_edge_imports_no_batch_code_and_no_private_validators():
    """_io reads files and settings: it never imports _many (the tuner) or _app, and the
    shared validators are public names of schema.py."""
    src = ROOT / "src" / "jaxdse"
    for path in sorted((src / "_io").glob("*.py")):
        bad = {i for i in imports(path) if i.startswith(("..many", ".._many", ".._app"))}
        assert not bad, (path.name, bad)
    for path in (src / "_io" / "config.py", src / "_app" / "fleet_file.py"):
        private = {i for i in imports(path) if ":_" in i and "schema" in i or "config:_" in i}
        assert not private, (path.name, private)
