"""Assignment and seed correspondence (irdic.calibration.correspondence) on synthetic targets."""

import numpy as np
import pytest

from irdic.calibration import match_seeds
from irdic.calibration.correspondence import assign
from irdic.errors import ConfigError

from ._targets import book_order, uv_of


def test_assign_is_one_to_one_and_gated():
    pred = np.array([[0.0, 0.0], [10.0, 0.0], [np.nan, np.nan], [50.0, 50.0]])
    det = np.array([[10.4, 0.0], [0.3, 0.1], [9.0, 0.0], [80.0, 80.0]])
    mi, di = assign(pred, det, 2.0)
    assert mi.tolist() == [0, 1] and di.tolist() == [1, 0]


def test_match_seeds(target, detections):
    ids = target.markers.marker.values
    x = target.markers.x.values
    pix = target.truth.marker_pixel.values
    D = uv_of(detections)
    rng = np.random.default_rng(1)
    pick = [0, 9, 23, 44, 61, 80]  # both wings
    seeds = {int(ids[i]): (pix[i] + rng.uniform(-3, 3, 2)).tolist() for i in pick}
    mi, di, model = match_seeds(D, x, ids, seeds)
    true_mi, true_di = assign(pix, D, 1.0)
    assert mi.tolist() == true_mi.tolist() and di.tolist() == true_di.tolist()
    assert np.abs(model.project(x) - pix).max() < 0.2
    # string keys (from YAML/JSON) name the same markers
    mi2, _, _ = match_seeds(D, x, ids, {str(k): v for k, v in seeds.items()})
    assert mi2.tolist() == mi.tolist()


def test_match_seeds_errors(target, detections):
    ids = target.markers.marker.values
    x = target.markers.x.values
    pix = target.truth.marker_pixel.values
    D = uv_of(detections)
    pick = [0, 9, 23, 44, 61, 80, 70]
    seeds = {int(ids[i]): pix[i].tolist() for i in pick}
    with pytest.raises(ConfigError, match=r"not in the marker file: \['1000', '999'\]"):
        match_seeds(D, x, ids, {**seeds, 999: [1, 2], 1000: [3, 4]})
    with pytest.raises(ConfigError, match="at least 6 markers .* got 5"):
        match_seeds(D, x, ids, dict(list(seeds.items())[:5]))
    # one seed off by 25 px, then two seeds swapped: contradictory, and the culprits are named
    bad = dict(seeds)
    k23 = int(ids[23])
    bad[k23] = (pix[23] + [25.0, 0.0]).tolist()
    with pytest.raises(ConfigError, match=rf"contradict each other.*worst is seed {k23} at .* \(2\d.\d px off\)"):
        match_seeds(D, x, ids, bad)
    more = {**seeds, **{int(ids[i]): pix[i].tolist() for i in (30, 50)}}
    k44, k61 = int(ids[44]), int(ids[61])
    more[k44], more[k61] = seeds[k61], seeds[k44]
    with pytest.raises(ConfigError, match=rf"contradict each other.*worst are seed ({k44}|{k61}) .* and seed ({k44}|{k61}) "):
        match_seeds(D, x, ids, more)
    wing = target.book.marker_wing[book_order(target)]
    one_wing = {int(ids[i]): pix[i].tolist() for i in np.flatnonzero(wing == 0)[::6]}
    with pytest.raises(ConfigError, match="coplanar"):
        match_seeds(D, x, ids, one_wing)
    with pytest.raises(ConfigError, match=r"pair \[u, v\]"):
        match_seeds(D, x, ids, {**seeds, int(ids[5]): [1.0]})


def test_far_off_seed_is_named_with_its_distance(target, detections):
    ids = target.markers.marker.values
    x = target.markers.x.values
    pix = target.truth.marker_pixel.values
    D = uv_of(detections)
    pick = [0, 9, 23, 44, 61, 80]
    seeds = {int(ids[i]): pix[i].tolist() for i in pick}
    k = int(ids[44])
    seeds[k] = [1000.0, 760.0]  # far outside the target
    d = np.hypot(*(D - [1000.0, 760.0]).T).min()
    with pytest.raises(ConfigError, match=rf"seed for marker {k} at \(1000\.0, 760\.0\) is {d:.1f} px from any "
                                          r"detected blob \(detections are \d+\.\d px apart\)") as exc:
        match_seeds(D, x, ids, seeds)
    assert "coplanar" not in str(exc.value) and "rank" not in str(exc.value)


def test_collinear_seed_markers_are_called_collinear(target, detections):
    ids = target.markers.marker.values
    D = uv_of(detections)
    # six markers of the target moved onto one line in the DIC frame (e.g. a wrong column in the export)
    x = target.markers.x.values.copy()
    pick = [0, 9, 23, 44, 61, 80]
    x[pick] = np.array([1.0, 2.0, 3.0]) * np.arange(6)[:, None]
    seeds = {int(ids[i]): D[np.argmin(np.hypot(*(D - target.truth.marker_pixel.values[i]).T))].tolist()
             for i in pick}
    with pytest.raises(ConfigError, match=r"the 6 seed markers are \(nearly\) collinear"):
        match_seeds(D, x, ids, seeds)
