"""The ``jaxdse`` command line: the demo's output contract, figures an engineer can read, the
installed console script (help, exit status 2), command mix-ups, ``--strict``, the compile
cache folder, and no host callback in the compiled assessment."""

import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")


@pytest.mark.slow
def test_demo_command_writes_contract(demo_run):
    rc, out, printed, summary = demo_run
    assert rc == 0
    assert "H ref" in printed and "verdict" in printed and "auto" in printed and "cross" in printed
    names = [e["name"] for e in summary["recordings"]]
    assert names == ["auto", "cross"]
    for e in summary["recordings"]:
        for key in ("a1", "a2", "H_s", "H_ci95", "D", "verdict", "reasons", "a2_reference",
                    "H_reference_s", "online", "identification", "smape_percent", "n_samples",
                    "duration_s"):
            assert key in e
        assert "convergence_time_s" in e["online"]
        assert set(e["smape_percent"]) == {"x2_observer", "x2_playback", "I_t", "P_t", "Q_t"}
        header = (out / f"estimates_{e['name']}.csv").read_text().splitlines()[0]
        assert header == ("time_s,delta_rad,x2_hat_rad_s,x2_meas_rad_s,e_q_prime_pu,a1_hat,a2_hat,"
                          "t_e_pu,t_m_pu,e_f_pu,i_t_pu,p_t_pu,q_t_pu,x2_sim_rad_s,i_t_sim_pu,p_t_sim_pu,q_t_sim_pu")
        for fig in ("convergence", "x2", "playback"):
            assert (out / f"{fig}_{e['name']}.png").stat().st_size > 10_000


@pytest.mark.slow
def test_figures_have_labelled_axes_with_units(ambient, plant, estimate_jit, tmp_path, monkeypatch):
    import matplotlib.pyplot as plt

    import jaxdse as jd
    from jaxdse._app.report import plot_estimates

    est = estimate_jit(ambient.recording, plant, jd.ObserverConfig())
    labels = []
    monkeypatch.setattr(plt, "close", lambda fig: labels.extend(
        (ax.get_xlabel(), ax.get_ylabel()) for ax in fig.axes))
    plot_estimates(est, "t", tmp_path, float(plant.machine.omega_s))
    ylabels = [y for _, y in labels]
    assert all("[" in y and "]" in y for y in ylabels), ylabels
    assert any("time [s]" == x for x, _ in labels)


@pytest.mark.slow
def test_help_teaches(tmp_path):
    """Through the installed console script, in a real process: the entry point works, --help
    teaches, and bad input is exit status 2 with one line on stderr (the other CLI tests call
    ``main`` in-process)."""
    exe = shutil.which("jaxdse") or str(Path(sys.executable).parent / "jaxdse")
    res = subprocess.run([exe, "demo", "--help"], capture_output=True, text=True)
    assert res.returncode == 0 and "summary.json" in res.stdout and "example" in res.stdout
    res = subprocess.run([exe, "run", str(tmp_path / "nope.toml")], capture_output=True, text=True)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 2 and len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert lines[0].startswith("jaxdse: error:") and "nope.toml" in lines[0] and "does not exist" in lines[0]


ROOT = Path(__file__).resolve().parents[2]


def one_line_error(capsys) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("jaxdse: error:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_run_on_a_fleet_file_and_fleet_on_a_run_config_name_the_other_command(tmp_path, capsys):
    from jaxdse._app.cli import main

    fleet_file = ROOT / "experiments" / "andes_bench" / "fleet_ieee14.toml"
    assert main(["run", str(fleet_file), "--out", str(tmp_path / "o")]) == 2
    line = one_line_error(capsys)
    assert "fleet_ieee14.toml" in line and "use `jaxdse fleet" in line
    run_config = ROOT / "examples" / "csv_positive_sequence.toml"
    assert main(["fleet", str(run_config), "--out", str(tmp_path / "o")]) == 2
    line = one_line_error(capsys)
    assert "csv_positive_sequence.toml" in line and "use `jaxdse run" in line
    assert not (tmp_path / "o").exists()


def test_fleet_strict_exits_3_unless_every_unit_is_identified(tmp_path, capsys, monkeypatch):
    """The exit status from fleet.json's units (the estimation itself is test_fleet's)."""
    from jaxdse._app import fleet, fleet_file
    from jaxdse._app.cli import main

    units = [{"name": "B1_G1", "verdict": "identified"}, {"name": "B2_G1", "verdict": "weakly identified"}]
    monkeypatch.setattr(fleet_file, "load_fleet", lambda path: path)
    monkeypatch.setattr(fleet, "run_fleet", lambda fl, out: {"units": units})
    argv = ["fleet", "f.toml", "--out", str(tmp_path)]
    assert main(argv) == 0
    assert main(argv + ["--strict"]) == 3
    assert "--strict: 1 unit(s) not identified: B2_G1" in capsys.readouterr().err
    units[1]["verdict"] = "identified"
    assert main(argv + ["--strict"]) == 0


def test_compilation_cache_folder(tmp_path):
    """`jaxdse` keeps compiled code in $JAXDSE_CACHE_DIR, else $XDG_CACHE_HOME/jaxdse/xla;
    JAXDSE_CACHE_DIR=off turns the cache off."""
    # One interpreter for the three settings (each start imports JAX): the cache folder is
    # reset between them, as a fresh process has none.
    script = textwrap.dedent("""
        import json, os, sys
        import jax
        from jaxdse._app.cli import compilation_cache
        for extra in json.loads(sys.argv[1]):
            for k in ("JAXDSE_CACHE_DIR", "XDG_CACHE_HOME"):
                os.environ.pop(k, None)
            os.environ.update(extra)
            jax.config.update("jax_compilation_cache_dir", None)
            print(compilation_cache())
    """)
    env = {k: v for k, v in os.environ.items()
           if k not in ("JAXDSE_CACHE_DIR", "XDG_CACHE_HOME", "JAX_COMPILATION_CACHE_DIR")}
    cases = [{"JAXDSE_CACHE_DIR": str(tmp_path / "c")}, {"XDG_CACHE_HOME": str(tmp_path / "x")},
             {"JAXDSE_CACHE_DIR": "off"}]
    res = subprocess.run([sys.executable, "-c", script, json.dumps(cases)], capture_output=True, text=True,
                         env=env, check=True)
    expected = [str(tmp_path / "c"), str(tmp_path / "x" / "jaxdse" / "xla"), "None"]
    assert res.stdout.strip().splitlines()[-3:] == expected
    assert (tmp_path / "c").is_dir()


@pytest.mark.slow
def test_assessment_holds_no_host_callback(cut25, plant):
    """A host callback (diffrax's runtime check of t0, t1 and dt0, were they traced) keeps an
    executable out of JAX's persistent cache: the whole assessment must hold none."""
    import jax

    import jaxdse as jd

    def prims(jaxpr):
        for e in jaxpr.eqns:
            yield e.primitive.name
            for p in e.params.values():
                for sub in p if isinstance(p, (list, tuple)) else [p]:
                    inner = getattr(sub, "jaxpr", sub)
                    if hasattr(inner, "eqns"):
                        yield from prims(inner)
                    elif hasattr(getattr(inner, "jaxpr", None), "eqns"):
                        yield from prims(inner.jaxpr)

    closed = jax.make_jaxpr(lambda r: jax.tree_util.tree_leaves(jd.assess(r, plant)))(cut25)
    names = set(prims(closed.jaxpr))
    assert "scan" in names and "while" in names  # the walk reaches the solver's loops
    assert not {n for n in names if "callback" in n}, names


@pytest.mark.parametrize("argv,words", [
    (["demo", "--duration", "-10"], ["demo: --duration -10", "10-3600 s"]),
    (["demo", "--duration", "0"], ["demo: --duration 0"]),
    (["demo", "--duration", "nan"], ["demo: --duration nan"]),
    (["demo", "--duration", "1e9"], ["demo: --duration 1e+09"]),
    (["demo", "--seed", "-1"], ["demo: --seed -1", ">= 0"]),
    (["monitor", "examples/monitor.toml", "--duration", "0"], ["monitor: --duration 0", "> 0"]),
    (["monitor", "examples/monitor.toml", "--duration", "inf"], ["monitor: --duration inf"]),
])
def test_numeric_options_out_of_range_are_one_line(argv, words, capsys):
    """Checked before any work (nothing simulated, read or compiled): exit 2, one line."""
    from jaxdse._app.cli import main

    assert main(argv) == 2
    line = one_line_error(capsys)
    assert all(w in line for w in words), line


def _help(argv, capsys) -> str:
    from jaxdse._app.cli import main

    with pytest.raises(SystemExit) as e:
        main([*argv, "--help"])
    assert e.value.code == 0
    return capsys.readouterr().out


def test_help_lists_match_the_registries_and_readme(capsys):
    """--help names the .raw revisions and every model jaxdse simulates from the registries, as
    README does; the top-level help shows the planner's path check -> fleet -> validate -> monitor."""
    from jaxdse._io.psse import MACHINE_FIELDS, SUPPORTED_RAW_REVISIONS
    from jaxdse._models.exciters import EXCITERS
    from jaxdse._models.governors import GOVERNORS
    from jaxdse._models.machines import MACHINES
    from jaxdse._models.stabilisers import STABILISERS

    revs = f"{min(SUPPORTED_RAW_REVISIONS)}-{max(SUPPORTED_RAW_REVISIONS)}"
    top = _help([], capsys)
    path = top.split("a planner's path")[1].split("examples:")[0]
    steps = [path.index(f"jaxdse {c} ") for c in ("check", "fleet", "validate", "monitor")]
    assert steps == sorted(steps), path
    assert revs in path and "jaxdse demo" in top and "jaxdse run" in top and "jaxdse tune" in top
    readme = (ROOT / "README.md").read_text()
    simulated = [*MACHINES, *EXCITERS, *STABILISERS, *GOVERNORS]
    for command in ("fleet", "check"):
        text = _help([command], capsys)
        assert "{" + "RAW_REVISIONS}" not in text and "{SIMULATED}" not in text and "rev 32/33" not in text
        assert f"rev {revs}" in text, command
        listed = text.split("Models jaxdse simulates")[1].split("\n\n")[0]
        missing = [m for m in simulated if not re.search(rf"\b{m}\b", listed)]
        assert not missing, f"{command} --help lacks {missing}"
    fleet = _help(["fleet"], capsys).split("Records the estimator's plant is built from")[1].split("\n\n")[0]
    assert all(re.search(rf"\b{m}\b", fleet) for m in [*MACHINE_FIELDS, *GOVERNORS]), fleet
    assert f"revision {min(SUPPORTED_RAW_REVISIONS)}" in readme
    not_in_readme = [m for m in simulated if not re.search(rf"\b{m}\b", readme)]
    assert not not_in_readme, f"README does not list {not_in_readme}"
