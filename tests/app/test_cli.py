import json
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")


def test_demo_command_writes_contract(tmp_path):
    out = tmp_path / "demo"
    res = subprocess.run([sys.executable, "-m", "jaxdse._app.cli", "demo", "--out", str(out),
                          "--duration", "120"], capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    assert "a2 ref" in res.stdout and "auto" in res.stdout and "cross" in res.stdout
    summary = json.loads((out / "summary.json").read_text())
    names = [e["name"] for e in summary["recordings"]]
    assert names == ["auto", "cross"]
    for e in summary["recordings"]:
        for key in ("a1", "a2", "H_s", "D", "a2_reference", "H_reference_s", "convergence_time_s",
                    "smape_percent", "n_samples", "duration_s"):
            assert key in e
        assert set(e["smape_percent"]) == {"x2_observer", "x2_playback", "I_t", "P_t", "Q_t"}
        header = (out / f"estimates_{e['name']}.csv").read_text().splitlines()[0]
        assert header == ("time_s,delta_rad,x2_hat_rad_s,x2_meas_rad_s,e_q_prime_pu,a1_hat,a2_hat,"
                          "t_e_pu,t_m_pu,e_f_pu,x2_sim_rad_s,i_t_sim_pu,p_t_sim_pu,q_t_sim_pu")
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
    res = subprocess.run([sys.executable, "-m", "jaxdse._app.cli", "demo", "--help"],
                         capture_output=True, text=True)
    assert res.returncode == 0 and "summary.json" in res.stdout and "example" in res.stdout
