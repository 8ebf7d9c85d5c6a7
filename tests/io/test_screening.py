"""The spike screen (``_io/measurement.py``, step 5) on what a 30 frames/s PMU records of a
plant in a disturbance: a fault's 2-frame voltage dip answered by the current (and a 3-frame dip
whose current decays within it, answered at its first frame only), a line trip's
steps, and a large electromechanical swing are kept whole; a glitch in one channel is masked;
stale (repeated) frames in noisy data are masked, and a noise-free recording's repeats kept.
Synthetic recordings written as CSV and read through ``jd.read_measurement``."""

import numpy as np
import pytest

import jaxdse as jd

FPS = 30.0
T = np.arange(int(40 * FPS) + 1) / FPS
EVENT = 10.0


def recording(tmp_path, kind, glitch=None, seed=0):
    """The screening report of :func:`read`."""
    return read(tmp_path, kind, glitch, seed)[1]["screening"]


def read(tmp_path, kind, glitch=None, seed=0, stale=(), noise=True):
    """|V|, angle, |I|, angle (pu, deg) of a plant around an event at 10 s, 0.05 % TVE noise
    (or none); ``stale``: (first, last) frame ranges that repeat frame ``first`` exactly, or
    frame ``last + 1`` scaled by 0.98 where ``first`` is 0 (a simulator's frames before its
    first solution, as NASPI OSL case 1 opens). Returns ``(segments, data_quality)``."""
    rng = np.random.default_rng(seed)
    after = T >= EVENT
    x = np.where(after, T - EVENT, 0.0)
    swing = np.exp(-0.4 * x) * np.sin(2 * np.pi * 1.75 * x)   # 1.75 Hz: 17 frames a period
    vm = np.ones_like(T) * 1.01
    va = np.full_like(T, -8.0)
    im = np.full_like(T, 0.9)
    ia = np.full_like(T, -5.6)
    if kind == "swing":                                           # a forced oscillation
        va = va + after * 2.0 * swing
        im = im + after * 0.3 * swing
        ia = ia + after * 4.0 * swing
    if kind in ("fault", "fault3", "trip"):
        vm = vm - 0.012 * after
        va = va + after * (3.3 + 2.0 * swing)
        im = im + after * (0.3 * swing - 0.15 * np.exp(-3 * x))
        ia = ia + after * ((1.0 if kind == "fault3" else 3.0) + 4.0 * swing)
    if kind == "fault":                                           # 2 frames at 50 %, then the trip
        during = (T >= EVENT - 2 / FPS) & (T < EVENT)
        vm = np.where(during, 0.5, vm)
        im = np.where(during, 2.5, im)
        ia = np.where(during, -70.0, ia)
    if kind == "fault3":                                          # 3 frames at 30 %, the current decays
        during = (T >= EVENT - 3 / FPS) & (T < EVENT)
        vm = np.where(during, 0.3, vm)
        im[during] = [2.0, 1.4, 1.1]                               # its angle unchanged
    if glitch is not None:
        column, at, factor = glitch
        {"vm": vm, "im": im}[column][int(at * FPS)] *= factor
    sd = 0.0005 / np.sqrt(2) if noise else 0.0
    v = vm * np.exp(1j * np.deg2rad(va)) * (1 + sd * (rng.standard_normal(T.size) + 1j * rng.standard_normal(T.size)))
    i = im * np.exp(1j * np.deg2rad(ia)) * (1 + sd * (rng.standard_normal(T.size) + 1j * rng.standard_normal(T.size)))
    for first, last in stale:
        v[first:last + 1] = v[last + 1] * 0.98 if first == 0 else v[first]
        i[first:last + 1] = i[last + 1] * 0.98 if first == 0 else i[first]
    path = tmp_path / f"{kind}.csv"
    np.savetxt(path, np.column_stack([T, np.abs(v), np.rad2deg(np.angle(v)), np.abs(i),
                                      np.rad2deg(np.angle(i))]),
               delimiter=",", header="time_s,VM,VA,IM,IA", comments="", fmt="%.9g")
    spec = jd.MeasurementSpec(file=(str(path),), columns={
        "time": "time_s", "v_mag": "VM", "v_ang": "VA", "i_mag": "IM", "i_ang": "IA"},
        location="terminal", voltage_unit="pu", current_unit="pu", angle_unit="deg",
        f_nominal_hz=60.0, s_base_mva=100.0)
    return jd.read_measurement(spec)


@pytest.mark.parametrize("kind", ["swing", "trip", "fault", "fault3"])
def test_an_event_is_kept_whole(tmp_path, kind):
    assert recording(tmp_path, kind)["masked_samples"] == 0


@pytest.mark.parametrize("glitch", [("im", 13.0, 0.3), ("vm", 5.0, 0.9), ("im", 30.0, 1.3),
                                    ("vm", 12.0, 0.95)])
def test_a_glitch_in_one_channel_is_masked(tmp_path, glitch):
    # (during the swing the Hampel scale is the swing's: a dropout to 30 %, not a 30 % dip)
    s = recording(tmp_path, "fault", glitch=glitch)
    assert s["masked_samples"] == 1, s
    column = {"im": "IM", "vm": "VM"}[glitch[0]]
    assert s["spikes"][column]["samples"] == 1


def test_stale_frames_in_noisy_data_are_masked(tmp_path):
    # 4 frames at the start repeat a value 2 % low (OSL case 1 opens so); one frame in the
    # middle and two after the event repeat the frame before them (a PDC holding its last value)
    segments, q = read(tmp_path, "trip", stale=[(0, 3), (200, 201), (400, 402)])
    s = q["screening"]
    assert s["stale_frames"]["VM, IM"] == {"samples": 4 + 2 + 3, "first_row": 2}, s
    assert s["masked_samples"] == 9
    (t0, rec), = segments
    assert t0 == pytest.approx(4 / FPS)                    # the run at the start is trimmed
    assert np.min(np.asarray(rec.v_mag_pu)) > 0.99         # none of the stale 2 % low frames left
    assert [g["length_s"] for g in q["bridged_gaps"]] == pytest.approx([2 / FPS, 3 / FPS], abs=1e-6)


def test_repeats_of_noise_free_data_are_kept(tmp_path):
    # flat before the event, every frame repeats: the data's nature, not stale frames
    segments, q = read(tmp_path, "trip", noise=False)
    assert "stale_frames" not in q["screening"]
    assert q["screening"]["masked_samples"] == 0
    assert segments[0][0] == 0.0
