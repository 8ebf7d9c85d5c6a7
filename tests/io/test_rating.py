"""The recording against what the machine can carry (issue 19, item 4): a sustained apparent
power above the rating, a current beyond IEEE C50.13's short-time capability, or a reactive
power outside the capability curve is a scale or angle-reference mistake, refused with the
numbers; a short overload (a fault, a swing) and any operating point inside the curve pass."""

import numpy as np
import pytest

import jaxdse as jd

RATE = 10.0                                       # frames/s
MACHINE = jd.Machine()                            # 1100 MVA, x_d = 1.8 pu
V_KV = 400.0
I_RATED_A = float(MACHINE.s_rated_mva) * 1e6 / (np.sqrt(3) * V_KV * 1e3)
SPEC = jd.MeasurementSpec(file=(), columns={"time": "t", "v_mag": "VM", "v_ang": "VA", "i_mag": "IM",
                                            "i_ang": "IA"},
                          v_base_kv=V_KV, s_base_mva=float(MACHINE.s_rated_mva), min_segment_s=20.0)


def table(s_pu, duration_s=300.0, seed=0) -> jd.Table:
    """A recording at 1 pu voltage whose complex power [pu of the rating] is ``s_pu(t)``."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 1.0 / RATE)
    s = np.broadcast_to(s_pu(t), t.shape) * (1 + 1e-3 * rng.standard_normal(t.size))
    va = 0.01 * np.cumsum(rng.standard_normal(t.size)) / RATE          # degrees, a slow walk
    vm = V_KV * (1 + 1e-3 * rng.standard_normal(t.size))
    i = np.conj(s) * I_RATED_A                                          # S = V conj(I), V = 1 pu
    return jd.Table(source="pmu.csv", first_row=2,
                    columns={"t": t, "VM": vm, "VA": va, "IM": np.abs(i), "IA": va + np.degrees(np.angle(i))})


def refused(tab) -> str:
    with pytest.raises(jd.InputError) as err:
        jd.condition(tab, SPEC, MACHINE)
    msg = str(err.value)
    assert msg.startswith("pmu.csv, column 'IM'") and "\n" not in msg
    return msg


@pytest.mark.parametrize("s_pu", [0.818 + 0.15j, 1.0 + 0.0j, 0.6 + 0.6j, 0.1 + 0.75j, 0.3 - 0.5j,
                                  1.05 + 0.3j])
def test_operating_points_inside_the_capability_pass(s_pu):
    segments, quality = jd.condition(table(lambda t: s_pu), SPEC, MACHINE)
    assert quality["median_current_pu_machine"] == pytest.approx(abs(s_pu), rel=0.01)


def test_peak_instead_of_rms_is_refused_with_the_numbers():
    msg = refused(table(lambda t: np.sqrt(2) * (0.818 + 0.15j)))
    assert "median apparent power is 1.18 pu of the rating" in msg and "1100 MVA" in msg
    assert "peak instead of" in msg and "s_rated_mva" in msg


def test_a_swing_passes_and_a_sustained_overload_is_refused():
    """1.3 x rated current for 20 s (a swing after a fault) passes; for 80 s, (I^2 - 1) t is
    55 s against C50.13's 41.4 s: refused, naming the rows of the run (those more than half a
    second inside it: a second above the margin makes a run, not a spike)."""
    def overload(seconds):
        return lambda t: np.where((t >= 100.0) & (t < 100.0 + seconds), 1.3, 0.8) + 0.1j
    jd.condition(table(overload(20.0)), SPEC, MACHINE)
    msg = refused(table(overload(80.0)))
    assert "short-time capability" in msg and "IEEE C50.13" in msg
    start, stop = (int(x) for x in msg.split("row ")[1].split(":")[0].split("-"))
    assert abs(start - (2 + 100.5 * RATE)) <= 1 and abs(stop - (2 + 179.5 * RATE)) <= 2
    assert "for 78.9 s" in msg


@pytest.mark.parametrize("s_pu, words", [(0.15 - 0.818j, "steady-state stability limit"),
                                         (0.2 + 0.95j, "field-heating limit")])
def test_reactive_power_outside_the_capability_curve_is_refused(s_pu, words):
    """A current angle 80-90 degrees off (a phase mapping) turns P into Q: outside the curve."""
    msg = refused(table(lambda t: s_pu))
    assert words in msg and "current angle reference" in msg and "power factor" in msg
