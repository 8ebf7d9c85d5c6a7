"""Chunked (streaming) estimation equals the one-shot run to 1e-9."""

import numpy as np
import pytest

import jaxdse as jd
from jaxdse._many.batch import pad_recording

FIELDS = ("t_s", "v_mag_pu", "v_ang_rad", "i_mag_pu", "i_ang_rad", "f_hz")


@pytest.mark.slow
@pytest.mark.parametrize("case", ["fast", "adaptive-no-f-wrapped"])
def test_stream_equals_one_shot(ambient, plant, case, estimate_jit):
    host = {k: np.asarray(getattr(ambient.recording, k))[:3100] for k in FIELDS}
    if case == "fast":
        st = jd.Settings.fast(keep="final", qss_window_s=5.0)
    else:  # derived frequency, angles wrapped to (-pi, pi], adaptive steps
        st = jd.Settings(keep="final", qss_window_s=5.0)
        host["f_hz"] = None
        for k in ("v_ang_rad", "i_ang_rad"):
            host[k] = np.angle(np.exp(1j * (host[k] + 40.0)))
    rec = jd.Recording(**host)
    cfg = jd.ObserverConfig(gamma1=3000.0, gamma2=3000.0)
    # as padded below (to its own length): the fast case shares the short-chunk test's compile
    one = estimate_jit(pad_recording(rec, 3100), plant, cfg, st, None, ambient.truth.a2)
    seen = []
    got = jd.estimate_stream(rec, plant, cfg, st, None, ambient.truth.a2, chunk_s=13.0,
                             progress=lambda d, t: seen.append((d, t)))
    assert seen[-1] == (2 * 3100, 2 * 3100) and len(seen) == 2 * 5  # 5 chunks of 650 samples
    for name in ("a1", "a2", "h_s", "d_pu_s", "t_ref_pu", "convergence_time_s", "a2_hat", "a1_hat",
                 "time_s", "log_contraction_end"):
        np.testing.assert_allclose(getattr(got, name), getattr(one, name), rtol=1e-9, atol=1e-12,
                                   err_msg=name)
    np.testing.assert_allclose(np.array(got.smape), np.array(one.smape), rtol=1e-9)
    for name in ("converged", "excited", "online", "solver_ok", "torque_balanced"):
        assert bool(getattr(got, name)) == bool(getattr(one, name)), name


@pytest.mark.slow
@pytest.mark.parametrize("remainder", [1, 2, 3, 7])
def test_stream_short_last_chunk(ambient, plant, remainder, estimate_jit):
    """4 chunks of 650 samples and 1 to 7 more: a last slice of fewer than 8 samples (5 of
    halo + 1 or 2) joins the chunk before it, one of 8 or more stays a chunk of its own."""
    from jaxdse._many.stream import MIN_SLICE_SAMPLES

    total = 4 * 650 + remainder
    rec = jd.Recording(**{k: np.asarray(getattr(ambient.recording, k))[:total] for k in FIELDS})
    st = jd.Settings.fast(keep="final", qss_window_s=5.0)
    cfg = jd.ObserverConfig(gamma1=3000.0, gamma2=3000.0)
    # The one-shot run on the recording padded to 3100 samples: one compilation for every
    # remainder (padding is masked by n_samples).
    one = estimate_jit(pad_recording(rec, 3100), plant, cfg, st, None, ambient.truth.a2)
    seen = []
    got = jd.estimate_stream(rec, plant, cfg, st, None, ambient.truth.a2, chunk_s=13.0,
                             progress=lambda d, t: seen.append((d, t)))
    merged = remainder + st.derivative_half_width < MIN_SLICE_SAMPLES
    assert merged == (remainder <= 2)
    assert seen[-1] == (2 * total, 2 * total) and len(seen) == 2 * (4 if merged else 5)
    n_blocks = -(-total // st.block_samples)
    assert got.a2_hat.shape == (n_blocks,)
    for name in ("time_s", "a1_hat", "a2_hat"):
        np.testing.assert_allclose(getattr(got, name), getattr(one, name)[:n_blocks], rtol=1e-9,
                                   atol=1e-12, err_msg=name)
    for name in ("a1", "a2", "h_s", "d_pu_s", "t_ref_pu", "convergence_time_s", "log_contraction_end"):
        np.testing.assert_allclose(getattr(got, name), getattr(one, name), rtol=1e-9, atol=1e-12,
                                   err_msg=name)
    np.testing.assert_allclose(np.array(got.smape), np.array(one.smape), rtol=1e-9)
    for name in ("converged", "excited", "online", "solver_ok", "torque_balanced"):
        assert bool(getattr(got, name)) == bool(getattr(one, name)), name


@pytest.mark.slow
def test_stream_rejects_short_chunks_and_trajectories(ambient, plant):
    with pytest.raises(ValueError, match="qss_window_s"):
        jd.estimate_stream(ambient.recording, plant, jd.ObserverConfig(), jd.Settings(keep="final"),
                           chunk_s=2.0)
    with pytest.raises(ValueError, match="final"):
        jd.estimate_stream(ambient.recording, plant, jd.ObserverConfig(), jd.Settings())
