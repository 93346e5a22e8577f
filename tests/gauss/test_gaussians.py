"""clvis.gauss.gaussians' device records (kernels_cl/gauss/gaussians.cl)
against clvis.reference.gauss.gaussians, exactly, on every device and both
work shapes: the records and boxes in input order, and their gather."""

import numpy as np
import pyopencl.array as cla

from clvis.gauss.gaussians import GAUSSIAN_DTYPE, Gaussians, gather_records, gaussian_records
from clvis.gauss.points import frames_along
from clvis.reference.gauss import gaussians as ref


def _random(n, seed=0):
    rng = np.random.default_rng(seed)
    rot = frames_along(rng.normal(size=(n, 3)))
    return Gaussians(
        rng.normal(size=(n, 3)),
        rng.uniform(0.0, 0.3, (n, 3)),
        rot,
        rng.uniform(-1, 2, n),
        rng.uniform(0, 1, n),
    )


def test_records_and_boxes(queue):
    g = _random(700, seed=1)
    records, boxes, event = gaussian_records(queue, g, 2.5)
    assert event is not None
    recs = records.get().view(GAUSSIAN_DTYPE)
    mean, value, w, opac = ref.gaussian_records(g.means, g.scales, g.rotations, g.values, g.opacities)
    np.testing.assert_array_equal(recs["mean"], mean)
    np.testing.assert_array_equal(recs["value"], value)
    np.testing.assert_array_equal(recs["w"], w)
    np.testing.assert_array_equal(recs["opacity"], opac)
    np.testing.assert_array_equal(boxes.get(), ref.gaussian_boxes(g.means, g.scales, g.rotations, 2.5))


def test_gather_records(queue):
    g = _random(300, seed=2)
    records, _, _ = gaussian_records(queue, g, 3.0)
    order = np.random.default_rng(3).permutation(g.n).astype(np.uint32)
    out = gather_records(queue, records, cla.to_device(queue, order), g.n)
    want = records.get().view(GAUSSIAN_DTYPE)[order]
    np.testing.assert_array_equal(out.get().view(GAUSSIAN_DTYPE), want)


def test_no_gaussians(queue):
    g = Gaussians(np.zeros((0, 3)), np.zeros((0, 3)))
    records, boxes, event = gaussian_records(queue, g, 3.0)
    assert event is None and records.nbytes == GAUSSIAN_DTYPE.itemsize and boxes.shape == (1, 6)
    assert gather_records(queue, records, cla.zeros(queue, 1, np.uint32), 0).nbytes == GAUSSIAN_DTYPE.itemsize
