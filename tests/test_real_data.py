"""Real measured hysteresis nobody here generated: the piezo slice in data_samples/piezo."""

from pathlib import Path

import numpy as np

from endocal.runs.aligned import load_aligned

PIEZO = Path(__file__).resolve().parents[1] / "data_samples" / "piezo" / "piezo_aligned.csv"


def test_piezo_slice_loads_as_an_aligned_table_and_shows_hysteresis():
    data = load_aligned(PIEZO)
    assert data.axes == ["piezo"] and len(data.table) == 4000
    cmd, meas = data.cmd_deg("piezo"), data.meas_deg("piezo")
    rising = np.gradient(cmd) > 0
    # Same drive voltage, opposite directions: a hysteretic actuator sits on two branches.
    bins = np.linspace(1.2, 2.4, 7)  # mid-range voltages, visited in both directions every cycle
    gaps = []
    for lo, hi in zip(bins[:-1], bins[1:]):
        sel = (cmd >= lo) & (cmd < hi)
        gaps.append(meas[sel & rising].mean() - meas[sel & ~rising].mean())
    # Sensor noise from the sample-to-sample jitter after removing the smooth trend.
    noise = np.std(np.diff(meas, 2)) / np.sqrt(6)
    assert noise < 0.5
    assert min(abs(g) for g in gaps) > 20 * noise, (gaps, noise)
    assert np.all(np.sign(gaps) == np.sign(gaps[0]))  # one loop orientation throughout
