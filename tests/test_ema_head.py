"""Head correction and frames (cassi_fit.ema.head): the rigid fit recovers known motions
(far from the identity, so a fit that did nothing would fail), with untracked references,
at each level the references allow; degenerate references are refused per frame; the
bite-plane frame and the midsagittal plane."""

import numpy as np
import pytest

from cassi_fit.ema import head


def _rotation(rng, max_deg):
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = np.deg2rad(rng.uniform(0.5, 1.0) * max_deg)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def test_kabsch_recovers_known_motions_and_ignores_untracked_points():
    rng = np.random.default_rng(1)
    config = rng.normal(scale=50.0, size=(5, 3))
    rots = np.stack([_rotation(rng, 40.0) for _ in range(8)])
    shifts = rng.normal(scale=30.0, size=(8, 3))
    # the frames' references: config moved by the inverse motion, so R, t bring them back
    refs = np.einsum("nji,nmj->nmi", rots, config[None] - shifts[:, None])
    refs[2, 1] = np.nan  # one reference lost in one frame
    fits = head.fit_references(refs, config, "full")
    assert fits.ok.all()
    np.testing.assert_allclose(fits.rotation, rots, atol=1e-10)
    np.testing.assert_allclose(fits.translation, shifts, atol=1e-9)
    assert np.nanmax(fits.residual) < 1e-9
    assert head.rotation_angle_deg(rots).min() > 15.0  # the identity would be far off


def test_two_d_needs_two_references_and_recovers_the_planar_motion():
    config = np.array([[0.0, 0.0], [15.0, 61.0]])
    theta = np.deg2rad(12.0)
    rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    refs = (config - [3.0, -2.0]) @ rot  # R^T (q - t) for each reference
    fits = head.fit_references(refs[None], config, "full")
    np.testing.assert_allclose(fits.rotation[0], rot, atol=1e-12)
    np.testing.assert_allclose(fits.translation[0], [3.0, -2.0], atol=1e-12)
    assert head.reference_level(2, 2) == "full" and head.reference_level(3, 2) == "two"


def test_collinear_references_fix_no_rotation_in_3d():
    config = np.array([[0.0, 0, 0], [10.0, 0, 0], [20.0, 0, 0]])
    fits = head.fit_references(config[None], config, "full")
    assert not fits.ok[0] and np.isnan(fits.residual[0])
    moved = head.apply(fits, np.ones((1, 2, 3)))
    assert np.isnan(moved).all()  # those frames' sensors become untracked


def test_two_references_remove_all_but_the_rotation_about_their_line():
    rng = np.random.default_rng(4)
    config = np.array([[0.0, 0.0, 0.0], [0.0, 70.0, 0.0]])
    tilt = _rotation(rng, 20.0)
    refs = (config - [1.0, 2.0, 3.0]) @ tilt
    fits = head.fit_references(refs[None], config, "two")
    moved = np.einsum("ij,mj->mi", fits.rotation[0], refs) + fits.translation[0]
    np.testing.assert_allclose(moved, config, atol=1e-9)  # the references are put back
    one = head.fit_references(refs[None, :1], config[:1], "translation")
    np.testing.assert_allclose(one.rotation[0], np.eye(3))
    np.testing.assert_allclose(one.translation[0], config[0] - refs[0])


def test_reference_configuration_is_refined_past_a_noisy_first_frame():
    rng = np.random.default_rng(2)
    config = rng.normal(scale=40.0, size=(4, 3))
    refs = np.repeat(config[None], 9, axis=0)
    refs[0] += rng.normal(scale=0.5, size=(4, 3))  # the first complete frame is off
    refined = head.reference_configuration(refs, "full")
    # shape (distances between references) from the median, not from frame 0
    d = lambda p: np.linalg.norm(p[:, None] - p[None], axis=-1)  # noqa: E731
    np.testing.assert_allclose(d(refined), d(config), atol=1e-9)
    assert head.reference_configuration(np.full((3, 4, 3), np.nan), "full") is None


def test_bite_frame_and_midsagittal_plane():
    # a bite plate in a device frame: toolkit x forward, y up, z left
    m = np.array([[0.0, 0, -1], [1, 0, 0], [0, 1, 0]])  # device = m @ (x, y, z_left)
    origin = np.array([5.0, -100.0, 150.0])
    dev = lambda p: m @ np.asarray(p, float) + origin  # noqa: E731
    frame = head.bite_frame(dev([0, 0, 0]), dev([-42, 0, 0]), dev([8, 70, 0]) - dev([0, 0, 0]),
                            left=dev([-38, 0, 22]), right=dev([-38, 0, -22]))
    np.testing.assert_allclose(frame.apply(dev([10.0, 5.0, 3.0])), [10.0, 5.0, 3.0], atol=1e-12)
    # without left/right sensors: the lateral axis from the midline plane, sign by anatomy
    normal, _ = head.fit_plane(np.array([dev([0, 0, 0]), dev([-42, 0, 0]), dev([8, 70, 0]),
                                         dev([10, 15, 0])]))
    frame2 = head.bite_frame(dev([0, 0, 0]), dev([-42, 0, 0]),
                             dev([8, 70, 0]) - dev([0, 0, 0]), lateral=normal)
    np.testing.assert_allclose(np.abs(frame2.apply(dev([10.0, 5.0, 3.0]))), [10, 5, 3],
                               atol=1e-9)
    np.testing.assert_allclose(frame2.apply(dev([10.0, 5.0, 0.0])), [10, 5, 0], atol=1e-9)
    assert head.fit_plane(np.array([[0.0, 0, 0], [1, 1, 1], [2, 2, 2]])) is None


@pytest.mark.parametrize("forward, up, expect", [((1.0, 0.0), (0.0, 1.0), (3.0, 4.0)),
                                                 ((-1.0, 0.0), (0.0, 1.0), (-3.0, 4.0))])
def test_two_d_frames(forward, up, expect):
    frame = head.frame_from_axes(np.array(forward), np.array(up), np.zeros(2), "test")
    np.testing.assert_allclose(frame.apply(np.array([3.0, 4.0])), expect)
