"""The COM low-pass written in NumPy (to keep scipy.signal out of the CLI) against SciPy as the oracle."""
import numpy as np
import pytest
from scipy.signal import butter, sosfiltfilt

from froude.machine.forces import butter_lowpass, filtfilt


@pytest.mark.parametrize("order", [1, 2, 3, 4])
@pytest.mark.parametrize("fs", [24.0, 30.0, 120.0, 480.0])
def test_filtfilt_matches_scipy(order, fs):
    rng = np.random.default_rng(order * 1000 + int(fs))
    x = np.cumsum(rng.normal(size=(400, 3)), axis=0) + 5.0
    ref = sosfiltfilt(butter(order, 8.0, fs=fs, output="sos"), x, axis=0, padtype=None)
    got = filtfilt(butter_lowpass(order, 8.0, fs), x)
    assert np.abs(got - ref).max() < 1e-10


def test_constant_signal_passes_unchanged():
    x = np.full((50, 2), 3.25)
    assert np.allclose(filtfilt(butter_lowpass(2, 8.0, 120.0), x), 3.25, atol=1e-12)
