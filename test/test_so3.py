"""SO(3) tools: identities, round trips, and accuracy near 0 and pi."""
import math

import numpy as np
import pytest

from geoctl_ros.core.geometry import so3

pytestmark = pytest.mark.odroid

rng = np.random.default_rng(42)


def random_rotations(n, scale=3.0):
    return [so3.exp(rng.normal(size=3) * scale) for _ in range(n)]


def test_hat_vee_cross():
    for _ in range(20):
        x, y = rng.normal(size=3), rng.normal(size=3)
        assert np.allclose(so3.hat(x) @ y, np.cross(x, y))
        assert np.allclose(so3.cross(x, y), np.cross(x, y))
        assert np.allclose(so3.vee(so3.hat(x)), x)
        assert np.allclose(so3.hat(x), -so3.hat(x).T)


@pytest.mark.parametrize('angle', [0.0, 1e-12, 1e-7, 1e-4, 0.3, 2.0, math.pi - 1e-2,
                                   math.pi - 1e-6, math.pi - 1e-12, math.pi])
def test_exp_log_round_trip_at_angle(angle):
    for _ in range(20):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        R = so3.exp(axis * angle)
        assert np.allclose(R.T @ R, np.eye(3), atol=1e-14)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-14)
        w = so3.log(R)
        assert np.linalg.norm(w) == pytest.approx(angle, abs=1e-12)
        assert np.allclose(so3.exp(w), R, atol=1e-13)
        assert so3.angle(R) == pytest.approx(angle, abs=1e-12)
        if 0.0 < angle < math.pi - 1e-6:   # axis is unique away from pi
            assert np.allclose(w, axis * angle, atol=1e-10)


def test_exp_matches_series_for_small_angles():
    w = np.array([3e-5, -2e-5, 1e-5])
    W = so3.hat(w)
    series = np.eye(3) + W + W @ W / 2 + W @ W @ W / 6
    assert np.allclose(so3.exp(w), series, atol=1e-18)


def test_quaternion_round_trip_and_ros_order():
    # 90 deg about z in ROS order (x, y, z, w)
    q = [0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)]
    assert np.allclose(so3.quat_to_rot(q) @ [1, 0, 0], [0, 1, 0])
    for R in random_rotations(200) + [so3.exp([math.pi, 0, 0]), so3.exp([0, 0, math.pi])]:
        q = so3.rot_to_quat(R)
        assert q[3] >= 0.0
        assert np.linalg.norm(q) == pytest.approx(1.0)
        assert np.allclose(so3.quat_to_rot(q), R, atol=1e-14)
        assert np.allclose(so3.quat_to_rot(-q), R, atol=1e-14)   # double cover


def test_project_returns_nearest_rotation():
    R = random_rotations(1)[0]
    noisy = R + 1e-3 * rng.normal(size=(3, 3))
    P = so3.project(noisy)
    assert np.allclose(P.T @ P, np.eye(3), atol=1e-14)
    assert np.linalg.det(P) == pytest.approx(1.0)
    assert np.linalg.norm(P - R) < 2e-3
    reflected = np.diag([1.0, 1.0, -1.0])
    assert np.linalg.det(so3.project(reflected)) == pytest.approx(1.0)


def test_batched_products_round_each_pair_as_a_stack_of_one_and_are_what_they_say():
    """A batch of runs must fly exactly as the runs one by one (the campaign's replays and the
    scenario runner's batch of one rest on it): each pair of a stacked product rounds as the
    same pair in a stack of one, wherever it falls in memory (OpenBLAS's Prescott kernel rounds
    by alignment: the products do not go to BLAS), and each is the product its name says.
    """
    rng = np.random.default_rng(5)
    Ms, vs, ws = rng.normal(size=(64, 3, 3)), rng.normal(size=(64, 3)), rng.normal(size=(64, 3))
    Ns, L = rng.normal(size=(64, 3, 3)), rng.normal(size=(5, 9))
    M, v = Ms[0], vs[0]
    explicit = np.array([[sum(Mk[i, j] * vk[j] for j in range(3)) for i in range(3)]
                         for Mk, vk in zip(Ms, vs)])
    one = [slice(k, k + 1) for k in range(64)]           # run k as a stack of one
    cases = [
        (so3.matvec(Ms, vs), [so3.matvec(Ms[k], vs[k])[0] for k in one], explicit),
        (so3.matvec(M, vs), [so3.matvec(M, vs[k])[0] for k in one], vs @ M.T),
        (so3.matvec(Ms, v), [so3.matvec(Ms[k], v)[0] for k in one], Ms @ v),
        (so3.matvec(L, Ns.reshape(64, 9)), [so3.matvec(L, Ns.reshape(64, 9)[k])[0] for k in one],
         Ns.reshape(64, 9) @ L.T),
        (so3.vecmat(vs, Ms), [so3.vecmat(vs[k], Ms[k])[0] for k in one],
         np.array([Mk.T @ vk for Mk, vk in zip(Ms, vs)])),
        (so3.vecmat(vs, M), [so3.vecmat(vs[k], M)[0] for k in one], vs @ M),
        (so3.vecmat(v, Ms), [so3.vecmat(v, Ms[k])[0] for k in one],
         np.array([Mk.T @ v for Mk in Ms])),
        (so3.matmul(Ms, Ns), [so3.matmul(Ms[k], Ns[k])[0] for k in one],
         np.array([a @ b for a, b in zip(Ms, Ns)])),
        (so3.matmul(Ms, M), [so3.matmul(Ms[k], M)[0] for k in one], Ms @ M),
        (so3.dot(vs, ws), [so3.dot(vs[k], ws[k])[0] for k in one], (vs * ws).sum(axis=1)),
        (so3.transpose(Ms), [so3.transpose(a) for a in Ms], np.array([Mk.T for Mk in Ms])),
    ]
    for batched, singles, meant in cases:
        assert np.array_equal(batched, np.array(singles))
        np.testing.assert_allclose(batched, meant, rtol=0, atol=1e-14)
    # a stack whose pairs sit at every alignment in memory: an offset view of a bigger buffer
    buf = rng.normal(size=64 * 9 + 1)
    shifted = buf[1:].reshape(64, 3, 3)
    assert np.array_equal(so3.matmul(shifted, Ns)[1::2],
                          np.array([so3.matmul(shifted[k], Ns[k])[0] for k in one[1::2]]))


def test_a_stack_of_exponentials_rounds_as_a_stack_of_one_whatever_its_size():
    """The campaign's runs.csv must not depend on how runs are batched: each rotation of a stack
    is the one a stack of one gives, bit for bit, and both are the single-rotation exp (and
    exp_apply is exp's matrix applied) to rounding.
    """
    rng = np.random.default_rng(11)
    ws = np.concatenate([rng.normal(size=(40, 3)), 1e-6 * rng.normal(size=(8, 3)),
                         np.zeros((1, 3))])
    vs = rng.normal(size=(len(ws), 3))
    stacked, applied = so3.exp(ws), so3.exp_apply(ws, vs)
    for k, (w, v) in enumerate(zip(ws, vs)):
        assert np.array_equal(stacked[k], so3.exp(ws[k:k + 1])[0])
        assert np.array_equal(applied[k], so3.exp_apply(ws[k:k + 1], vs[k:k + 1])[0])
        np.testing.assert_allclose(stacked[k], so3.exp(w), rtol=0, atol=1e-15)
        np.testing.assert_allclose(applied[k], so3.exp(w) @ v, rtol=0, atol=1e-14)
        np.testing.assert_allclose(so3.exp_apply(w, v), so3.exp(w) @ v, rtol=0, atol=1e-14)
