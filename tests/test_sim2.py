import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from zfloc_stream.geometry.sim2 import Sim2

finite = st.floats(-50, 50)
transforms = st.builds(
    lambda s, th, x, y: Sim2(s, th, (x, y)), st.floats(0.2, 5), st.floats(-10, 10), finite, finite
)


@given(transforms, transforms)
def test_compose_matches_sequential_application(a, b):
    pts = np.array([[0.0, 0.0], [1.0, 2.0], [-3.0, 0.5]])
    np.testing.assert_allclose((a @ b).apply(pts), a.apply(b.apply(pts)), atol=1e-7)
    np.testing.assert_allclose((a @ b).matrix(), a.matrix() @ b.matrix(), atol=1e-7)


@given(transforms)
def test_inverse_params_and_matrix_round_trip(a):
    pts = np.array([[0.3, -1.0], [4.0, 2.0]])
    np.testing.assert_allclose(a.inverse().apply(a.apply(pts)), pts, atol=1e-7)
    b = Sim2.from_params(a.params())
    c = Sim2.from_matrix(a.matrix())
    for other in (b, c):
        np.testing.assert_allclose(other.matrix(), a.matrix(), atol=1e-9)


def test_apply_pose_rotates_heading():
    x, y, yaw = Sim2(2.0, np.pi / 2, (1.0, 0.0)).apply_pose(1.0, 0.0, 0.1)
    np.testing.assert_allclose([x, y, yaw], [1.0, 2.0, np.pi / 2 + 0.1])
