"""System inertia per area (jaxdse._core.inertia): exact sums on hand-made fleets, the
interval's coverage by Monte Carlo, and no NaN where an area has no online unit."""

import math

import numpy as np
import pytest

from jaxdse._core.inertia import AreaInertia, InertiaSettings, InertiaUnit, Z95, area_inertia


def _fleet():
    return [
        InertiaUnit("g1", "north", 100.0, True, h_model_s=5.0, h_s=4.0, h_ci95=(3.8, 4.4), age_s=0.0,
                    measured=True),
        InertiaUnit("g2", "north", 200.0, True, h_model_s=3.0),
        InertiaUnit("g3", "north", 50.0, False, h_model_s=6.0),                     # offline
        InertiaUnit("w1", "north", 80.0, True, kind="ibr_following"),
        InertiaUnit("g4", "south", 300.0, True, h_model_s=4.0, h_s=4.5, h_ci95=(4.0, 5.0), age_s=40.0,
                    measured=True),                                                  # stale
        InertiaUnit("f1", "south", 100.0, True, kind="grid_forming", h_model_s=2.0),
    ]


def test_exact_sums_on_a_hand_made_fleet():
    s = InertiaSettings(model_uncertainty=0.1, largest_loss_mw=1000.0, f0_hz=50.0, stale_s=30.0,
                        floor_MWs=1500.0)
    rows, units = area_inertia(_fleet(), s, areas=["north", "south", "east"])
    north, south, east, system = rows
    assert [r.area for r in rows] == ["north", "south", "east", "system"]
    # north: 4*100 measured + 3*200 model; g3 offline; w1 0
    assert north.E_MWs == pytest.approx(1000.0)
    assert north.E_measured_MWs == pytest.approx(400.0) and north.measured_share == pytest.approx(0.4)
    assert north.E_commitment_MWs == pytest.approx(5 * 100 + 3 * 200)
    assert north.E_ci95[0] == pytest.approx(1000 - math.hypot(20.0, 60.0))
    assert north.E_ci95[1] == pytest.approx(1000 + math.hypot(40.0, 60.0))
    assert north.units_online == 3 and north.units_measured == 1 and north.below_floor is True
    assert north.rocof_hz_per_s == pytest.approx(50 * 1000 / 2000)
    assert north.rocof_ci95[0] == pytest.approx(25000 / north.E_ci95[1])
    # south: g4 stale -> its model 4*300; f1 virtual 2*100
    assert south.E_MWs == pytest.approx(1400.0) and south.measured_share == 0.0
    assert south.units_measured == 0 and south.units_stale == 1
    assert south.E_ci95[1] - 1400 == pytest.approx(math.hypot(120.0, 20.0))
    by = {u.name: u for u in units}
    assert by["g4"].source == "model (stale)" and by["g1"].source == "measured"
    assert by["g3"].source == "offline" and by["w1"].source == "ibr_following" and by["f1"].source == "model"
    # an area without units: E = 0, no NaN, RoCoF None with its reason
    assert east.E_MWs == 0.0 and east.E_ci95 == (0.0, 0.0) and east.measured_share is None
    assert east.rocof_hz_per_s is None and east.rocof_reason == "no online unit" and east.units_online == 0
    assert system.E_MWs == pytest.approx(2400.0) and system.E_measured_MWs == pytest.approx(400.0)
    assert system.E_commitment_MWs == pytest.approx(1100 + 1400)
    assert system.E_ci95[1] - 2400 == pytest.approx(math.sqrt(40**2 + 60**2 + 120**2 + 20**2))
    assert system.units_online == 5 and system.below_floor is False
    line = system.line(1.0)
    assert list(line) == ["t", "area", "E_MWs", "E_ci95", "measured_share", "E_commitment_MWs",
                          "rocof_hz_per_s", "units_online", "units_measured"]


def test_no_online_unit_and_no_loss_configured():
    s = InertiaSettings()
    rows, _ = area_inertia([InertiaUnit("g", "a", 100.0, False, h_model_s=5.0),
                            InertiaUnit("w", "b", 100.0, True, kind="ibr_following")], s)
    for r in rows:
        assert r.E_MWs == 0.0 and r.measured_share is None and r.rocof_hz_per_s is None
        assert all(math.isfinite(x) for x in r.E_ci95)
    assert rows[0].rocof_reason == "no largest_loss_mw configured"
    s = InertiaSettings(largest_loss_mw=100.0)
    rows, _ = area_inertia([InertiaUnit("w", "b", 100.0, True, kind="ibr_following")], s)
    assert rows[0].rocof_reason.startswith("no stored kinetic energy")
    # an online unit the case gives no H: 0, counted apart
    rows, units = area_inertia([InertiaUnit("x", "a", 100.0, True, h_model_s=None)], s)
    assert units[0].source == "no H record" and rows[0].units_without_h == 1 and rows[0].E_MWs == 0.0


def test_a_measured_h_without_interval_is_not_used():
    rows, units = area_inertia([InertiaUnit("g", "a", 100.0, True, h_model_s=5.0, h_s=9.0, h_ci95=None,
                                            age_s=0.0, measured=True)], InertiaSettings())
    assert units[0].source == "model (no interval)" and rows[0].E_MWs == pytest.approx(500.0)


def test_measured_half_widths_add_when_shared():
    units = [InertiaUnit("a", "x", 100.0, True, h_model_s=5.0, h_s=5.0, h_ci95=(4.0, 5.5), age_s=0.0, measured=True),
             InertiaUnit("b", "x", 100.0, True, h_model_s=5.0, h_s=5.0, h_ci95=(4.0, 5.5), age_s=0.0, measured=True),
             InertiaUnit("c", "x", 100.0, True, h_model_s=4.0)]
    shared = area_inertia(units, InertiaSettings(model_uncertainty=0.1))[0][-1]
    assert shared.E_ci95 == pytest.approx((1400 - math.hypot(200, 40), 1400 + math.hypot(100, 40)))
    indep = area_inertia(units, InertiaSettings(model_uncertainty=0.1, measured_errors="independent"))[0][-1]
    assert indep.E_ci95 == pytest.approx((1400 - math.sqrt(100**2 * 2 + 40**2), 1400 + math.sqrt(50**2 * 2 + 40**2)))
    with pytest.raises(ValueError, match="measured_errors"):
        InertiaSettings(measured_errors="correlated")


def _coverage(asymmetric: bool, truth_shared: bool, mode: str, draws: int = 2500) -> float:
    """Monte Carlo: a fleet of 40 units (25 measured, 15 on filed H) with known true H; each
    draw gives every unit an error inside its stated uncertainty (normal, or split normal with
    the stated lower and upper half-widths), shared by the measured units (one draw for all)
    where ``truth_shared``, independent otherwise; the estimate is truth + error and E's
    interval is built from the estimates' stated intervals with ``measured_errors = mode``
    (the first draws through :func:`area_inertia`, all through :func:`table_inertia`, which
    must agree). Returns the fraction of draws whose interval covers the true E."""
    from jaxdse._core.inertia import UnitTable, table_inertia

    rng = np.random.default_rng(0)
    n = 40
    s_mva = rng.uniform(50, 800, n)
    h_true = rng.uniform(2, 8, n)
    measured = np.arange(n) < 25
    rel = 0.15
    rel_lo = rng.uniform(0.03, 0.2, n)                      # measured units' relative half-widths
    rel_hi = rng.uniform(0.03, 0.2, n) if asymmetric else rel_lo
    settings = InertiaSettings(model_uncertainty=rel, measured_errors=mode)
    covered = 0
    e_true = float(np.sum(h_true * s_mva))
    for draw in range(draws):
        z = np.full(n, rng.standard_normal()) if truth_shared else rng.standard_normal(n)
        # split normal around the truth: a positive error (estimate above the truth) is bounded by
        # the stated lower half-width, a negative one by the upper
        err = np.where(z < 0, z * rel_hi, z * rel_lo) * h_true / Z95
        est = h_true + err
        filed = h_true * (1 + rel * rng.standard_normal(n) / Z95)   # independent filing errors
        lo, hi = est - rel_lo * h_true, est + rel_hi * h_true
        table = UnitTable(area=np.zeros(n, int), s_mva=s_mva, online=np.ones(n, bool),
                          ibr_following=np.zeros(n, bool), h_model_s=np.where(measured, h_true, filed),
                          measured=measured, h_s=np.where(measured, est, np.nan),
                          h_lo_s=np.where(measured, lo, np.nan), h_hi_s=np.where(measured, hi, np.nan),
                          age_s=np.where(measured, 0.0, np.inf))
        system = table_inertia(table, ["a"], settings)[-1]
        if draw < 3:
            units = [InertiaUnit(f"u{k}", "a", s_mva[k], True, h_model_s=h_true[k], h_s=est[k],
                                 h_ci95=(lo[k], hi[k]), age_s=0.0, measured=True) if measured[k]
                     else InertiaUnit(f"u{k}", "a", s_mva[k], True, h_model_s=filed[k]) for k in range(n)]
            assert area_inertia(units, settings)[0][-1].E_ci95 == pytest.approx(system.E_ci95, rel=1e-12)
        covered += system.E_ci95[0] <= e_true <= system.E_ci95[1]
    return covered / draws


@pytest.mark.parametrize("asymmetric", [False, True])
@pytest.mark.parametrize("mode", ["shared", "independent"])
def test_interval_covers_95_percent(asymmetric, mode):
    """Each combination covers 95 % (+-2 %, 2500 draws: 4.6 standard errors) when the errors are
    what it assumes; a linear sum of independent errors' half-widths would cover ~100 %."""
    coverage = _coverage(asymmetric, mode == "shared", mode)
    assert 0.93 <= coverage <= 0.97, coverage


def test_quadrature_undercovers_shared_errors():
    """Why "shared" is the default: when the measured units' errors move together (as on the
    ANDES ieee14 line trip), their intervals summed in quadrature cover far less than 95 %."""
    assert _coverage(False, True, "independent", draws=1000) < 0.85
    assert _coverage(False, False, "shared", draws=1000) > 0.99          # shared on independent errors: wide


@pytest.mark.parametrize("mode", ["shared", "independent"])
def test_table_inertia_equals_the_unit_by_unit_rules(mode):
    """The vectorised form (a live monitor's thousands of units) against the unit-by-unit one
    on a random fleet of every kind: offline, converters, no H record, measured fresh, stale,
    without interval, and an empty area."""
    from jaxdse._core.inertia import UnitTable, table_inertia

    rng = np.random.default_rng(1)
    n = 300
    areas = ["a", "b", "c", "empty"]
    units = []
    for k in range(n):
        kind = rng.choice(["synchronous", "synchronous", "grid_forming", "ibr_following", "no_h_record"])
        measured = kind in ("synchronous", "grid_forming") and rng.random() < 0.5
        h = rng.uniform(2, 8)
        ci = (h * 0.9, h * 1.2) if rng.random() < 0.9 else None
        units.append(InertiaUnit(f"u{k}", str(rng.choice(areas[:3])), float(rng.uniform(10, 900)),
                                 bool(rng.random() < 0.85), str(kind),
                                 None if kind in ("no_h_record", "ibr_following") else float(rng.uniform(2, 8)),
                                 h_s=h if measured else None, h_ci95=ci if measured else None,
                                 age_s=float(rng.uniform(0, 60)) if measured else None, measured=measured))
    settings = InertiaSettings(model_uncertainty=0.12, largest_loss_mw=500.0, stale_s=30.0, floor_MWs=1e4,
                               measured_errors=mode)
    expected, _ = area_inertia(units, settings, areas)

    def col(f, missing=np.nan):
        return np.array([missing if f(u) is None else f(u) for u in units], float)

    table = UnitTable(area=np.array([areas.index(u.area) for u in units]), s_mva=col(lambda u: u.s_mva),
                      online=np.array([u.online for u in units]),
                      ibr_following=np.array([u.kind == "ibr_following" for u in units]),
                      h_model_s=col(lambda u: u.h_model_s), measured=np.array([u.measured for u in units]),
                      h_s=col(lambda u: u.h_s), h_lo_s=col(lambda u: u.h_ci95 and u.h_ci95[0]),
                      h_hi_s=col(lambda u: u.h_ci95 and u.h_ci95[1]), age_s=col(lambda u: u.age_s, np.inf))
    got = table_inertia(table, areas, settings)
    assert [r.area for r in got] == [r.area for r in expected] == [*areas, "system"]
    for g, x in zip(got, expected):
        for field in AreaInertia._fields:
            a, b = getattr(g, field), getattr(x, field)
            if isinstance(b, float):
                assert a == pytest.approx(b, rel=1e-12, abs=1e-9), (field, g.area)
            elif isinstance(b, tuple):
                assert a == pytest.approx(b, rel=1e-12, abs=1e-9), (field, g.area)
            else:
                assert a == b, (field, g.area)
    assert expected[0].units_stale > 0 and expected[0].units_without_h > 0 and expected[0].units_measured > 0
