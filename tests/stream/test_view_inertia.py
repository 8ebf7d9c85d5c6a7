"""The live page's system inertia panel: E per area over time with its band, the commitment
figure, the floor and the alarm below it, served in state.json (no monitor, no stream)."""

import json
import urllib.request

from jaxdse._stream.view import PAGE, LiveView


def lines(t, e_sys, e_north):
    def one(area, e):
        return {"t": t, "area": area, "E_MWs": e, "E_ci95": [0.9 * e, 1.1 * e], "measured_share": 0.5,
                "E_commitment_MWs": 1.05 * e, "rocof_hz_per_s": None, "units_online": 4, "units_measured": 2}
    return [one("North", e_north), one("system", e_sys)]


def test_inertia_panel_state_and_alarm():
    view = LiveView(["1_1"], lambda: {"streams": []}, port=0, floor_MWs=15000.0)
    host, port = view.start()
    try:
        url = f"http://{host}:{port}/"
        state = json.loads(urllib.request.urlopen(url + "state.json", timeout=5).read())
        assert state["inertia"] is None                      # no line yet: no panel
        view.add_inertia(lines(100.0, 30000.0, 16000.0))
        view.add_inertia(lines(101.0, 29000.0, 14000.0))     # North falls below the floor
        state = json.loads(urllib.request.urlopen(url + "state.json", timeout=5).read())
        page = urllib.request.urlopen(url, timeout=5).read().decode()
    finally:
        view.stop()
    x = state["inertia"]
    assert x["floor_MWs"] == 15000.0
    assert [a["area"] for a in x["areas"]] == ["North", "system"]
    north, system = x["areas"]
    assert [p["E"] for p in north["history"]] == [16000.0, 14000.0]
    assert north["history"][-1]["lo"] == 0.9 * 14000.0 and north["history"][-1]["com"] == 1.05 * 14000.0
    assert north["latest"]["below_floor"] is True and system["latest"]["below_floor"] is False
    assert 'id="inertia"' in page and "BELOW FLOOR" in page and "function echart" in page
    assert page == PAGE


def test_inertia_panel_without_floor():
    view = LiveView([], lambda: {"streams": []})
    view.add_inertia(lines(5.0, 100.0, 50.0))
    x = view.state()["inertia"]
    assert x["floor_MWs"] is None and all(a["latest"]["below_floor"] is None for a in x["areas"])


def test_inertia_panel_renders_in_node(tmp_path):
    """The page's script run by node on a fake document: the panel of an area below its floor
    shows the alarm, E, its band and the floor line (skipped without node)."""
    import shutil
    import subprocess

    import pytest

    node = shutil.which("node")
    if node is None:
        pytest.skip("no node")
    script = PAGE.split("<script>")[1].split("</script>")[0].replace("tick();setInterval(tick,1000);", "")
    state = {"inertia": {"floor_MWs": 15000.0, "areas": [
        {"area": "system", "latest": {**lines(2.0, 14000.0, 1.0)[1], "below_floor": True},
         "history": [{"t": 1.0, "E": 16000.0, "lo": 14400.0, "hi": 17600.0, "com": 16800.0},
                     {"t": 2.0, "E": 14000.0, "lo": 12600.0, "hi": 15400.0, "com": 14700.0}]}]}}
    js = tmp_path / "page.js"
    js.write_text("const els={inertia:{innerHTML:''}};global.document={getElementById:id=>els[id]};\n"
                  + script + f"\ninertia({json.dumps(state)});console.log(els.inertia.innerHTML);\n")
    out = subprocess.run([node, str(js)], capture_output=True, text=True, timeout=30)
    assert out.returncode == 0, out.stderr
    html = out.stdout
    assert 'class="unit alarm" data-area="system"' in html and "BELOW FLOOR" in html
    assert "<b>14.000 GW s</b>" in html and "12.600 - 15.400" in html
    assert 'class="floor"' in html and "<polygon" in html and "stroke-dasharray" in html
