"""The demo tube's machine loads: linear kinematic hardening against hand-worked values."""

import math

import numpy as np

from irdic.synthetic.loads import hardening_stress
from irdic.synthetic.specimens import Tube


def test_hardening_stress_by_hand():
    E, sy, H = 200000.0, 300.0, 1000.0
    Et = E * H / (E + H)
    # elastic, at yield, plastic
    np.testing.assert_allclose(hardening_stress([0.001, 0.0015, 0.0115], [0, 0, 0], E, sy, H),
                               [200.0, 300.0, 300.0 + Et * 0.01], rtol=1e-12)
    # unloading from the plastic peak: elastic over 2 sigma_y, then reverse yield with E_t
    peak = 300.0 + Et * 0.01
    np.testing.assert_allclose(hardening_stress([0.0115] * 3, [0.001, 0.003, 0.004], E, sy, H),
                               [peak - 200.0, peak - 600.0, peak - 600.0 - Et * 0.001], rtol=1e-12)
    # an elastic loading unloads elastically down to -sigma_y
    np.testing.assert_allclose(hardening_stress([0.001, 0.001], [0.002, 0.003], E, sy, H),
                               [-200.0, -300.0 - Et * 0.0005], rtol=1e-12)


def test_demo_tube_loads_fit_a_100_kN_machine():
    tube = Tube()
    t = np.linspace(0.0, 10.0, 2001)
    F, T = tube.axial_force(t), tube.torque(t)
    area = math.pi * (tube.R**2 - tube.R_inner**2)
    assert 0.9 * 300.0 * area < F.max() < 100e3  # N: yielded, within the machine's range
    assert F.min() > -100e3 and abs(F[0]) < 1e-9
    r_m, w = 0.5 * (tube.R + tube.R_inner), tube.R - tube.R_inner
    assert 0.9 * 300.0 / math.sqrt(3.0) * 2 * math.pi * r_m**2 * w / 1000.0 < T.max() < 1000.0  # N m


def test_readme_quotes_the_demo_tube_peaks():
    import re
    from pathlib import Path

    text = " ".join((Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8").split())
    m = re.search(r"loaded to about (\d+) kN and (\d+) N m on a (\d+) mm tube", text)
    tube = Tube()
    t = np.linspace(0.0, 10.0, 4001)
    assert int(m[1]) == round(tube.axial_force(t).max() / 1000.0)
    assert int(m[2]) == round(tube.torque(t).max(), -1)
    assert int(m[3]) == round(2 * tube.R)
