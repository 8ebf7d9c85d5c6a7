"""The live monitor (jaxdse._stream.monitor, ``jaxdse monitor``) and its windowed identification
(jaxdse._core.windowed, jaxdse._stream.online), on loopback only.

* the windowed estimate of the shipped example (simulated, H = 6.18 s) is right and its
  interval covers the truth; how the stream is cut into chunks does not change H (the carried
  states are exact); a short gap is bridged, a long one restarts the unit's estimator;
* end to end: ``jaxdse pmu-sim`` (in a thread) serves the example with faults (dropped frames,
  STAT errors, a bad CRC, late frames, a configuration change, a long gap); the monitor reads
  it, and the recording it writes, read back by ``jaxdse run replay.toml`` through the file
  readers, gives the same updates to round-off;
* bad monitor files are refused in one line.
Every wait is bounded."""

import json
import math

import jax
import numpy as np
import pytest
from builders import example_cut

from jaxdse._app.cli import main
from jaxdse._core.windowed import WindowSettings
from jaxdse._io.config import load_config
from jaxdse._io.errors import InputError
from jaxdse._io.measurement import read_measurement
from jaxdse._stream import c37118 as c3
from jaxdse._stream import pmu_sim
from jaxdse._app.sources import load_monitor, load_source, replay_recording
from jaxdse._stream.monitor import Monitor
from jaxdse._stream.online import OnlineGroup

jax.config.update("jax_enable_x64", True)

H_TRUE = 6.18
ROWS = 3000  # 120 s at 25 frames/s
BASE = 1_700_000_000 * 25


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    """The example run configuration on its first 120 s: (config path, generator, recording)."""
    run = example_cut(tmp_path_factory.mktemp("mon"), ROWS)
    g = load_config(run).generators[0]
    (_, rec), = read_measurement(g.measurement, g.plant.machine)[0]
    return run, g, rec


def _head(rec, n):
    """The first ``n`` samples of ``rec``."""
    import dataclasses

    return dataclasses.replace(rec, **{k: None if getattr(rec, k) is None else np.asarray(getattr(rec, k))[:n]
                                       for k in ("t_s", "v_mag_pu", "v_ang_rad", "i_mag_pu", "i_ang_rad", "f_hz")})


def _feed(g, rec, window, usable=None):
    grp = OnlineGroup([g.name], [g.plant], [rec.location], 25.0, window)
    out = []
    for k in range(rec.t_s.shape[0]):
        ok = True if usable is None else bool(usable[k])
        out += grp.push(BASE + k, [rec.v_mag_pu[k]], [rec.v_ang_rad[k]], [rec.i_mag_pu[k]],
                        [rec.i_ang_rad[k]], [rec.f_hz[k]], [ok])
    return out


@pytest.mark.slow
def test_windowed_estimate_is_right_and_covers(example, monkeypatch):
    """H right and covered once the window is full; while it fills, the chunks only push their
    blocks (the segment's first call all the blocks its slice holds), with no window estimate."""
    import jaxdse._stream.online as online

    calls = []
    for name in ("_push", "_push_first", "_estimates"):
        real = getattr(online, name)
        monkeypatch.setattr(online, name, lambda *a, real=real, name=name: calls.append(name) or real(*a))
    _, g, rec = example
    window = WindowSettings(update_s=2.0, window_s=60.0)
    ups = _feed(g, rec, window)
    assert len(ups) > 20
    grp = OnlineGroup([g.name], [g.plant], [rec.location], 25.0, window)
    pushes = calls.index("_estimates")
    assert calls[0] == "_push_first" and calls[1:pushes] == ["_push"] * (window.blocks - grp.first_chunks)
    assert calls[pushes:] == ["_estimates"] + ["_push", "_estimates"] * (len(ups) - 1)
    first = ups[0]
    assert first.t - BASE / 25 >= 60.0 - 1e-9          # the first estimate once the window is full
    assert np.allclose(np.diff([u.t for u in ups]), 2.0)
    for u in ups:
        assert u.verdict == "identified", u
        assert abs(u.h_s / H_TRUE - 1) < 0.02
        assert u.h_ci95[0] <= H_TRUE <= u.h_ci95[1]
        assert u.age_s == 0.0 and u.segment == 1


@pytest.mark.slow
def test_chunks_do_not_change_h(example):
    """The same samples in chunks of 1 s or 2 s: the same sums, so the same H (the front end's
    context, the filters, the governor and its low-pass carry exactly across chunks; a
    lookahead of 4 s makes the backward pass's start-up negligible, 1e-15)."""
    _, g, rec = example
    rec = _head(rec, 1750)                                     # 70 s
    a = {u.t: u for u in _feed(g, rec, WindowSettings(update_s=1.0, window_s=50.0, lookahead_s=4.0))}
    b = {u.t: u for u in _feed(g, rec, WindowSettings(update_s=2.0, window_s=50.0, lookahead_s=4.0))}
    common = sorted(set(a) & set(b))
    assert common
    for t in common:
        assert a[t].h_s == pytest.approx(b[t].h_s, rel=1e-10)
        assert a[t].d_pu_s == pytest.approx(b[t].d_pu_s, rel=1e-8)


def test_filling_says_how_far_along_and_what_for(example):
    """Before its first chunk (nothing compiled yet): the stream time a unit's segment holds and
    the stream time its first update needs, from the segment's first sample, and why."""
    _, g, rec = example
    grp = OnlineGroup([g.name], [g.plant], [rec.location], 25.0, WindowSettings(update_s=1.0, window_s=20.0))
    have, need = grp.filling()
    assert have[0] == 0 and need[0] == pytest.approx(grp.first_update_samples() / 25)
    offset = 7                                             # the segment starts 7 frames before a chunk boundary
    for k in range(100):
        assert grp.push(BASE - offset + k, [rec.v_mag_pu[k]], [rec.v_ang_rad[k]], [rec.i_mag_pu[k]],
                        [rec.i_ang_rad[k]], [rec.f_hz[k]], [True]) == []
    have, need = grp.filling()
    assert have[0] == pytest.approx(4.0) and need[0] == pytest.approx((offset + grp.first_update_samples()) / 25)
    # 20 s window + 1 s lookahead after it + the halo, from the chunk boundary
    assert grp.first_update_samples() == 20 * 25 + 25 + grp.halo
    assert "a full 20 s window and the 1 s after it" in grp.wait_reason()


@pytest.mark.slow
def test_short_gaps_are_bridged_long_ones_restart(example):
    _, g, rec = example
    rec = _head(rec, 1750)                                     # 70 s
    usable = np.ones(1750, bool)
    usable[1000:1010] = False             # 0.4 s: bridged (max_gap_s 0.5)
    ups = _feed(g, rec, WindowSettings(update_s=1.0, window_s=20.0), usable)
    assert {u.segment for u in ups} == {1}
    assert all(u.h_ci95[0] <= H_TRUE <= u.h_ci95[1] for u in ups if u.h_s is not None)
    usable[1000:1020] = False             # 0.8 s: a new segment, whose window fills again
    ups = _feed(g, rec, WindowSettings(update_s=1.0, window_s=20.0), usable)
    second = [u for u in ups if u.segment == 2]
    assert {u.segment for u in ups} == {1, 2} and second
    assert second[0].t - (BASE + 1020) / 25 >= 20.0


def _pair_with_a_restart(example, monkeypatch):
    """70 s of the example for two units, unit 1 unusable for 0.8 s at 40 s (it restarts), with a
    1-row small batch for a group of 2 (``online.SMALL_SHARE``): (generator, recording, window,
    usable [samples, 2])."""
    from jaxdse._stream import online

    _, g, rec = example
    rec = _head(rec, 1750)
    usable = np.ones((1750, 2), bool)
    usable[1000:1020, 1] = False
    monkeypatch.setattr(online, "MIN_SMALL", 2)
    monkeypatch.setattr(online, "SMALL_SHARE", 2)
    return g, rec, WindowSettings(update_s=1.0, window_s=20.0), usable


@pytest.mark.slow
def test_few_ready_units_run_on_the_small_batch_with_the_same_result(example, monkeypatch):
    """A unit restarted by a long gap runs its chunks while the others wait for theirs: those
    chunks run on the group's small batch (its rows gathered, the results scattered back), and
    give each unit the updates it gets alone, to round-off (``online.SMALL_SHARE``: here a
    group of 2 units with a 1-row small batch)."""
    from jaxdse._stream import online

    g, rec, window, usable = _pair_with_a_restart(example, monkeypatch)
    taken = []
    take = online._take
    monkeypatch.setattr(online, "_take", lambda *a: taken.append(1) or take(*a))
    pair = OnlineGroup(["a", "b"], [g.plant] * 2, [rec.location] * 2, 25.0, window)
    assert pair.small == 1
    alone = [OnlineGroup([n], [g.plant], [rec.location], 25.0, window) for n in "ab"]
    assert alone[0].small == 0
    got = {"a": [], "b": []}
    want = {"a": [], "b": []}
    for k in range(1750):
        x = [rec.v_mag_pu[k], rec.v_ang_rad[k], rec.i_mag_pu[k], rec.i_ang_rad[k], rec.f_hz[k]]
        for u in pair.push(BASE + k, *[[v, v] for v in x], usable[k]):
            got[u.unit].append(u)
        for j, grp in enumerate(alone):
            for u in grp.push(BASE + k, *[[v] for v in x], [usable[k, j]]):
                want[u.unit].append(u)
    assert taken                                               # the small batch ran
    assert {u.segment for u in got["b"]} == {1, 2}
    for n in "ab":
        assert [u.t for u in got[n]] == [u.t for u in want[n]] and got[n]
        for u, w in zip(got[n], want[n]):
            assert (u.verdict, u.segment, u.samples) == (w.verdict, w.segment, w.samples)
            assert u.h_s == pytest.approx(w.h_s, rel=1e-12)
            assert u.h_ci95 == pytest.approx(w.h_ci95, rel=1e-12)
            assert u.d_pu_s == pytest.approx(w.d_pu_s, rel=1e-10)


@pytest.mark.slow
@pytest.mark.parametrize("every", [4, None])
def test_a_restarted_unit_waits_for_spare_time_and_others_do_not(example, monkeypatch, every):
    """With ``defer`` (the live monitor), a start and a unit restarted while another serves are
    background work: the serving unit's updates come at the same frames as without it, the
    deferred chunks run in ``catch_up`` (here every 4th frame, or never: then once their backlog
    reaches ``BACKGROUND_LAG_S``, here 2 s: a unit in service a chunk or more behind catches
    up in spare time too), and both units get the updates they get alone. The
    deferred group's estimates are dispatched, not waited for: read here at their frame
    (``collect(wait=True)``), as the monitor reads them once done."""
    from jaxdse._stream import online

    g, rec, window, usable = _pair_with_a_restart(example, monkeypatch)
    monkeypatch.setattr(online, "BACKGROUND_LAG_S", 2.0)
    now, later = (OnlineGroup(["a", "b"], [g.plant] * 2, [rec.location] * 2, 25.0, window, defer=d)
                  for d in (False, True))
    assert later.capacity == now.capacity + 50
    got = {False: [], True: []}
    deferred = 0
    for k in range(1750):
        x = [rec.v_mag_pu[k], rec.v_ang_rad[k], rec.i_mag_pu[k], rec.i_ang_rad[k], rec.f_hz[k]]
        for grp in (now, later):
            got[grp.defer] += [(k, u) for u in grp.push(BASE + k, *[[v, v] for v in x], usable[k])]
        got[True] += [(k, u) for u in later.collect(wait=True)]
        if later.behind():
            deferred += 1
            if every and k % every == 0:
                got[True] += [(k, u) for u in later.catch_up() + later.collect(wait=True)]
    while later.behind():
        got[True] += [(1750, u) for u in later.catch_up()]
    got[True] += [(1750, u) for u in later.collect(wait=True)]
    assert not later.waiting()
    # its chunks waited: for a catch_up (up to 3 frames each), or up to the lag (50 frames)
    assert deferred > (every or 30)
    for n in "ab":
        a, b = ([x for x in got[d] if x[1].unit == n] for d in (False, True))
        assert [u.t for _, u in a] == [u.t for _, u in b] and a
        for (_, u), (_, w) in zip(a, b):                       # to round-off (another batch)
            assert (u.verdict, u.segment, u.samples) == (w.verdict, w.segment, w.samples)
            assert u.h_s == pytest.approx(w.h_s, rel=1e-12) and u.h_ci95 == pytest.approx(w.h_ci95, rel=1e-12)
        if n == "a":   # its start was background too (late by at most the lag); in service: same frames
            assert all(0 <= kb - ka <= 50 + 1 for (ka, _), (kb, _) in zip(a, b))
            if every:   # without spare time it stays behind by a chunk or more, up to the lag
                assert [k for k, _ in a if k >= 1000] == [k for k, _ in b if k >= 1000]
        else:                                                  # restarted: later, by at most the lag
            late = [kb - ka for (ka, u), (kb, _) in zip(a, b) if u.segment == 2]
            assert late and max(late) > 0 and max(late) <= 50 + 1


@pytest.mark.slow
def test_a_deferred_groups_estimates_are_read_once_done_and_none_is_lost(example, monkeypatch):
    """With ``defer``, a window's estimate is dispatched and its updates are read when done
    (``collect``, and each push reads those done): none is lost or repeated, each unit's come in
    time order, the same as the group's that waits for each; at most ``MAX_PENDING`` wait."""
    from jaxdse._stream import online

    g, rec, window, usable = _pair_with_a_restart(example, monkeypatch)
    monkeypatch.setattr(online, "MAX_PENDING", 2)
    now, later = (OnlineGroup(["a", "b"], [g.plant] * 2, [rec.location] * 2, 25.0, window, defer=d)
                  for d in (False, True))
    got = {False: [], True: []}
    most = 0
    for k in range(1750):
        x = [rec.v_mag_pu[k], rec.v_ang_rad[k], rec.i_mag_pu[k], rec.i_ang_rad[k], rec.f_hz[k]]
        for grp in (now, later):
            got[grp.defer] += grp.push(BASE + k, *[[v, v] for v in x], usable[k])
        most = max(most, len(later.pending))
        if k % 50 == 0:
            got[True] += later.catch_up()
    while later.behind():
        got[True] += later.catch_up()
    got[True] += later.collect(wait=True)
    assert got[False] and not later.waiting() and most <= 2
    key = (lambda u: (u.unit, u.t))
    assert sorted(map(key, got[False])) == sorted(map(key, got[True]))
    for n in "ab":
        times = [u.t for u in got[True] if u.unit == n]
        assert times == sorted(times) and len(set(times)) == len(times)
    mine = {key(u): u for u in got[True]}
    for u in got[False]:
        w = mine[key(u)]
        assert (u.verdict, u.segment, u.samples) == (w.verdict, w.segment, w.samples)
        assert u.h_s == pytest.approx(w.h_s, rel=1e-12)


def test_deferred_chunks_go_to_the_computer_one_per_group_and_a_first_only_when_it_is_idle():
    """A stream's catch-up picks a group that has deferred chunks and whose previous chunk is
    computed; a segment's first chunk (the large one) only when no group is busy; ``force``
    (the stop's drain) takes any that has them."""
    from jaxdse._stream.monitor import _Stream

    class G:
        def __init__(self, name, behind, busy, first):
            self.name, self._behind, self._busy, self._first = name, behind, busy, first

        def behind(self):
            return self._behind

        def busy(self):
            return self._busy

        def first_behind(self):
            return self._first

        def catch_up(self):
            return [self.name]

    s = object.__new__(_Stream)
    s.groups = [(G("busy", True, True, False), None), (G("first", True, False, True), None)]
    assert s.can_catch_up(idle=True) and s.catch_up(idle=True) == ["first"]
    assert not s.can_catch_up(idle=False) and s.catch_up(idle=False) == []
    assert s.catch_up(force=True) == ["busy"]
    s.groups.append((G("next", True, False, False), None))
    assert s.can_catch_up(idle=False) and s.catch_up(idle=False) == ["next"]
    s.groups = [(G("done", False, False, False), None)]
    assert not s.can_catch_up(idle=True) and s.catch_up(force=True) == []


@pytest.mark.slow
def test_monitor_end_to_end_and_replay_equality(example, tmp_path):
    config, _, _ = example
    source = load_source(config)
    faults = [pmu_sim.Fault.parse(s) for s in (
        "drop@20+0.4", "error@25+0.2", "crc@30+0.2", "late=0.05@35+0.2", "stale@40+0.2", "config-change=2@45", "drop@75+2")]
    server = pmu_sim.PmuServer(source, port=0, speed=30.0, faults=faults)
    with server.serve_in_thread() as (host, port):
        (tmp_path / "mon.toml").write_text(
            f'fleet = "{config}"\nupdate_s = 1.0\nwindow_s = 20.0\n[stream]\nhost = "{host}"\nport = {port}\n'
            "timeout_s = 2.0\n[alarm]\nh_below_s = 7.0\n")
        lines = []
        mon = Monitor(load_monitor(tmp_path / "mon.toml"), tmp_path / "live", log=lines.append, progress_s=0.2)
        summary = mon.run(duration_s=8.0)
    live = [json.loads(x) for x in (tmp_path / "live" / "updates.jsonl").read_text().splitlines()]
    assert live and summary["updates"] == len(live)
    st = summary["streams"][0]
    assert st["config_changes"] == 1 and st["slots_without_frame"] >= 50 + 10
    # Each counter counts what it is named for: every data frame is used, late, repeated, off the
    # grid or beyond the reorder buffer (0.05 s late is within reorder_s: used); the decoder's
    # count of frames it decoded is not among what it rejected (the 5 frames with a bad CRC).
    assert st["data_frames"] == st["frames_used"] + st["late_frames"] + st["repeated_frames"] \
        + st["off_grid_frames"] + st["reorder_overflow_frames"]
    assert st["late_frames"] == st["repeated_frames"] == st["off_grid_frames"] == 0
    rejected = {k: v for k, v in st["decoder"].items() if k.startswith("frames_rejected_")}
    assert rejected.get("frames_rejected_crc") == server.stats["bad_crc"] == 5
    assert st["data_frames"] + st["frames_before_config"] + sum(rejected.values()) == server.stats["sent"]
    assert st["decoder"]["frames_decoded"] == st["data_frames"] + st["frames_before_config"] + 2   # + 2 CFG-2
    # The delay, on the stream's clock (30x real time): never below what the estimate waits for by
    # construction (its 1 s lookahead and the 0.2 s reorder buffer); the wall delay is it divided by
    # the pace measured then (arrivals stamped by the reader thread, late while XLA compiles).
    assert st["pace"] == pytest.approx(30.0, rel=0.2)
    assert min(x["delay_s"] for x in live) >= 1.2 - 1e-6
    assert all(20.0 < x["delay_s"] / x["wall_delay_s"] < 40.0 for x in live)
    # While the window fills: lines that say how far along and what the first estimate needs.
    # What it waited for: the compiler at the configuration, then (a line every 0.2 s while the
    # window fills, where the stream's 4 s of wall time were not spent queued behind the compiler)
    # the stream time the first estimate needs: from the first frame to the frame 1 s (the
    # lookahead) after the first window's end, that frame included.
    import re

    assert any("compiling the estimators' programs" in x for x in lines), lines
    filling = [x for x in lines if "filling their window" in x]
    assert all("a full 20 s window" in x for x in filling), lines
    needs = [float(re.search(r"of ([0-9.]+) s of stream time", x).group(1)) for x in filling[:1]]
    assert list(st["stale_samples"].values()) == [5]      # 40.0-40.16 s repeat the 39.96 s frame
    # The estimators restart at the configuration change (a new part of the recording) and at
    # the long gap (a new segment): each time, no update until the window is full again.
    import tomllib

    parts = tomllib.loads((tmp_path / "live" / "replay.toml").read_text())["replay"]["part"]
    assert len(parts) == 2
    t0 = parts[0]["index0"] / 25.0                        # the first frame's time
    for need in needs:
        assert need == pytest.approx(live[0]["t"] + 1.0 + 1 / 25 - t0, abs=0.051)
    ts = np.array([x["t"] for x in live]) - t0
    assert not np.any((ts > 45.5) & (ts < 45 + 20)) and not np.any((ts > 75.5) & (ts < 77 + 20))
    assert {x["segment"] for x in live} == {1, 2}
    for x in live:
        assert x["verdict"] in ("identified", "weakly identified"), x    # a 20 s window
        assert x["H_ci95"][0] <= H_TRUE <= x["H_ci95"][1]
        assert x["alarm"] is True                         # H below 7 s
    again = replay_recording(tmp_path / "live" / "replay.toml", tmp_path / "replayed")
    assert [x["t"] for x in again] == [x["t"] for x in live]
    for x, y in zip(live, again):
        assert y["H_s"] == pytest.approx(x["H_s"], rel=1e-9)
        assert y["H_ci95"] == pytest.approx(x["H_ci95"], rel=1e-9)
        assert y["segment"] == x["segment"]


@pytest.mark.parametrize("text, key", [
    ('update_s = 1.0', "fleet"),
    ('fleet = "{run}"\nwindow_s = 0.5', "window_s"),
    ('fleet = "{run}"\n[stream]\ntransport = "sctp"', "stream.transport"),
    ('fleet = "{run}"\n[stream]\nprotocol = "iec61850"', "stream.protocol"),
    ('fleet = "{run}"\n[stream]\nport = 1\nspeed = 2', "stream.speed"),
    ('fleet = "{run}"\n[stream.stations]\nnobody = "X"', "stream.stations.nobody"),
    ('fleet = "{run}"\n[inertia]\nstale_s = -1', "inertia.stale_s"),
    ('fleet = "{run}"\n[inertia]\nareas = "region"', "inertia.areas"),
    ('fleet = "{run}"\nrecord = "yes"', "record"),
])
def test_bad_monitor_files_are_refused_in_one_line(example, tmp_path, capsys, text, key):
    config, _, _ = example
    (tmp_path / "m.toml").write_text(text.replace("{run}", str(config)))
    with pytest.raises(InputError) as err:
        load_monitor(tmp_path / "m.toml")
    assert key in str(err.value) and "\n" not in str(err.value)
    capsys.readouterr()
    assert main(["monitor", str(tmp_path / "m.toml"), "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and key in err, err


def test_unreachable_stream_ends_cleanly(example, tmp_path):
    config, _, _ = example
    (tmp_path / "m.toml").write_text(f'fleet = "{config}"\n[stream]\nport = 9\ntimeout_s = 0.5\n')
    lines = []
    summary = Monitor(load_monitor(tmp_path / "m.toml"), tmp_path / "o", log=lines.append).run(duration_s=2.0)
    assert summary["updates"] == 0 and summary["streams"][0]["connect_failures"] >= 1
    assert any("reconnecting" in x for x in lines)
    assert math.isfinite(summary["wall_s"])


@pytest.mark.slow
def test_results_are_published_and_shown(example, tmp_path):
    """The virtual PMU: a C37.118 client reads CFG-2 (one station per unit, analogs H, H_LO,
    H_HI, D, AGE) and data frames whose analogs are the updates' values. The live view: its
    state as JSON, and the page as a person sees it (headless Chromium's DOM after its script
    ran; skipped where Chromium is absent)."""
    import shutil
    import subprocess
    import threading
    import time
    import urllib.request

    config, _, _ = example
    server = pmu_sim.PmuServer(load_source(config), port=0, speed=20.0)
    with server.serve_in_thread() as (host, port):
        (tmp_path / "mon.toml").write_text(
            f'fleet = "{config}"\nwindow_s = 20.0\n[stream]\nhost = "{host}"\nport = {port}\n'
            '[publish]\nport = 0\nidcode = 77\n[view]\nport = 0\n')
        mon = Monitor(load_monitor(tmp_path / "mon.toml"), tmp_path / "live", log=lambda line: None)
        th = threading.Thread(target=mon.run, args=(12.0,), daemon=True)   # the page read while it runs
        th.start()
        deadline = time.monotonic() + 10
        while (mon.publisher.bound is None) and time.monotonic() < deadline:
            time.sleep(0.05)
        with pmu_sim.PmuClient(*mon.publisher.bound, idcode=77, timeout=5.0) as client:
            cfg = client.config()
            assert [a.name for a in cfg.stations[0].analogs] == ["H", "H_LO", "H_HI", "D", "AGE"]
            assert cfg.stations[0].name == "unit1" and cfg.data_rate == 1
            client.start()
            frames = [f for f in client.frames(seconds=6.0) if isinstance(f, c3.DataFrame)]
        url = "http://{}:{}/".format(*mon.view.bound)
        state = json.loads(urllib.request.urlopen(url + "state.json", timeout=5).read())
        page = urllib.request.urlopen(url, timeout=5).read().decode()
        dom = None
        browser = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
        if browser:
            dom = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=3000",
                                  "--dump-dom", url], capture_output=True, text=True, timeout=60).stdout
        th.join(timeout=30)
    assert "<title>jaxdse monitor</title>" in page and "state.json" in page
    (u,) = state["units"]
    assert u["unit"] == "unit1" and u["history"] and u["latest"]["verdict"] == "identified"
    assert state["streams"][0]["frames_used"] > 0
    if dom is not None:
        assert 'data-unit="unit1"' in dom and ">identified<" in dom and "<svg" in dom, dom[-2000:]
    assert frames
    live = {round(x["t"], 6): x for x in map(json.loads, (tmp_path / "live" / "updates.jsonl").read_text().splitlines())}
    for f in frames:
        st = f.stations[0]
        x = live[round(c3.frame_time(f, cfg.time_base), 6)]
        assert c3.Stat.from_word(st.stat).data_error == 0 and not c3.Stat.from_word(st.stat).trigger
        assert st.analogs[0] == pytest.approx(x["H_s"], rel=1e-6)          # float32 on the wire
        assert st.analogs[1] == pytest.approx(x["H_ci95"][0], rel=1e-6)


@pytest.mark.slow
def test_one_streams_failure_costs_its_units_only(example, tmp_path):
    """Two streams (``tile = 2``: units unit1 and unit1~2, one per stream); the second stops
    after 2 s: its unit's updates stop and its thread keeps trying, the first's unit goes on.
    ``record = false``: no recording and no replay file, the updates all the same."""
    config, _, _ = example
    source = pmu_sim.tile(load_source(config), 2)
    a = pmu_sim.PmuServer(source, port=0, speed=20.0, loop=True)        # never ends by itself
    b = pmu_sim.PmuServer(source, port=0, speed=20.0, duration=2.0)
    with a.serve_in_thread() as (ha, pa), b.serve_in_thread() as (hb, pb):
        (tmp_path / "m.toml").write_text(
            f'fleet = "{config}"\nwindow_s = 10.0\ntile = 2\nrecord = false\n'
            f'[[stream]]\nhost = "{ha}"\nport = {pa}\nunits = ["unit1"]\n'
            f'[[stream]]\nhost = "{hb}"\nport = {pb}\nunits = ["unit1~2"]\ntimeout_s = 1.0\n')
        summary = Monitor(load_monitor(tmp_path / "m.toml"), tmp_path / "o", log=lambda x: None).run(6.0)
    ups = [json.loads(x) for x in (tmp_path / "o" / "updates.jsonl").read_text().splitlines()]
    first = [u["t"] for u in ups if u["unit"] == "unit1"]
    second = [u["t"] for u in ups if u["unit"] == "unit1~2"]
    assert first and max(first) > max(second, default=0) + 10       # 20x: 10 s of stream time
    s0, s1 = summary["streams"]
    assert s0["disconnects"] == 0 and s1["disconnects"] + s1["connect_failures"] >= 1
    assert not list((tmp_path / "o").glob("recording_*")) and not (tmp_path / "o" / "replay.toml").exists()


def test_stream_clock_measures_delay_in_stream_time():
    """The same stream at 1x and 5x real time, the same processing: the delay in stream time is
    the same (the window's wait, 1.2 s, plus the processing in stream time), the wall delay is it
    divided by the pace; the wall clock's own offset from the stream does not enter."""
    from jaxdse._stream.monitor import StreamClock

    out = {}
    for speed in (1.0, 5.0):
        clock = StreamClock()
        t0, w0 = 1_700_000_000.0, 500.0                  # stream time [s since 1970], monotonic [s]
        assert clock.now(w0) is None and clock.pace is None
        for k in range(251):                              # 10 s at 25 frames/s
            clock.frame(t0 + k / 25, w0 + k / 25 / speed)
        clock.frame(t0 + 3.0, w0 + 10.0 / speed)          # a late frame moves nothing
        assert clock.pace == pytest.approx(speed, rel=1e-12)
        processing = 0.002                                # [s of wall time] after the newest frame came
        u_t = t0 + 10.0 - 1.2                             # the update's window ended 1.2 s of stream before
        delay = clock.now(w0 + 10.0 / speed + processing) - u_t
        out[speed] = delay, delay / clock.pace
        clock.restart()                                   # a new connection: the last pace serves meanwhile
        assert clock.pace == pytest.approx(speed) and clock.now(w0) is None
    (d1, w1), (d5, w5) = out[1.0], out[5.0]
    assert d1 == pytest.approx(1.2 + 0.002, abs=1e-6) and d5 == pytest.approx(1.2 + 5 * 0.002, abs=1e-6)
    assert abs(d5 - d1) < 0.1 and w5 == pytest.approx(d5 / 5)


def test_stream_layer_imports_no_app_and_readers_not_each_other():
    """The house: the stream layer does not reach up into the application layer; the STTP
    module does not import the monitor that uses it; the experiment uses the public API."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    stream = root / "src" / "jaxdse" / "_stream"
    for path in stream.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                mod = "." * node.level + (node.module or "")
                names = [a.name for a in node.names]
                assert not mod.startswith(".._app") and "_app" not in mod.split("."), (path.name, mod)
                if path.name == "sttp.py":
                    assert mod not in (".monitor",) and not (mod == "." and "monitor" in names), mod
    text = (root / "experiments" / "monitor" / "run.py").read_text()
    assert "jaxdse._" not in text


def test_recording_rows_written_by_a_process_are_the_same_bytes(tmp_path):
    """A wide recording is formatted by a writer process (CsvRows): the same file, byte for byte,
    as written in the monitor's own process, and it reads back to the same float64 (NaN kept)."""
    from jaxdse._stream.monitor import CsvRows

    rng = np.random.default_rng(3)
    blocks = [rng.normal(size=(k, 7)) * 10.0 ** rng.integers(-8, 8, size=(k, 7)) for k in (3, 1, 5)]
    blocks[1][0, 2] = np.nan
    header = [f"c{j}" for j in range(7)]
    paths = []
    for in_process in (True, False):
        path = tmp_path / f"rows_{in_process}.csv"
        w = CsvRows(path, header, in_process=in_process)
        assert (w.proc is None) == in_process
        for b in blocks:
            w.write(b)
        w.close()
        paths.append(path)
    assert paths[0].read_bytes() == paths[1].read_bytes()
    back = np.genfromtxt(paths[1], delimiter=",", skip_header=1)
    np.testing.assert_array_equal(back, np.concatenate(blocks))
    with pytest.raises(ValueError, match="header has 7"):
        CsvRows(tmp_path / "bad.csv", header, in_process=True).write(np.zeros((1, 6)))
