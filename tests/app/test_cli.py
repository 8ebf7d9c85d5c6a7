import shutil
import subprocess
import sys
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


def test_figures_have_labelled_axes_with_units(ambient, plant, estimate_jit, tmp_path, monkeypatch):
    import matplotlib.pyplot as plt

    import jaxdse as jd
    from jaxdse import plot_estimates

    est = estimate_jit(ambient.recording, plant, jd.ObserverConfig())
    labels = []
    monkeypatch.setattr(plt, "close", lambda fig: labels.extend(
        (ax.get_xlabel(), ax.get_ylabel()) for ax in fig.axes))
    plot_estimates(est, "t", tmp_path)
    ylabels = [y for _, y in labels]
    assert all("[" in y and "]" in y for y in ylabels), ylabels
    assert any("time [s]" == x for x, _ in labels)


def test_help_teaches():
    """Through the installed console script: the entry point works and --help teaches."""
    exe = shutil.which("jaxdse") or str(Path(sys.executable).parent / "jaxdse")
    res = subprocess.run([exe, "demo", "--help"], capture_output=True, text=True)
    assert res.returncode == 0 and "summary.json" in res.stdout and "example" in res.stdout
