"""Bad input: a clear ValueError naming the problem, and the caller's arrays untouched."""

import numpy as np
import pytest
from meshdata import load, load2d

from core import PlaneFrame, untangle_and_smooth, untangle_and_smooth_3d


def square_pts():
    return np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]], float)


FAN = [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]


@pytest.mark.parametrize(
    ("faces", "message"),
    [
        ([], "no faces"),
        (np.zeros((0, 3), int), "no faces"),
        ([[0, 1, 9], [1, 2, 4]], "face 0 references node 9, but there are only 5 nodes"),
        ([[0, 1, -1]], "references node -1"),
        ([[0, 1, 4], [1, 2, 2, 4]], "face 1 repeats node 2"),
        ([[0, 1]], "face 0 has 2 vertices"),
        ([[0, 1, 4], [1, 4, 2], [2, 3, 4], [3, 0, 4]], "not consistently oriented"),
    ],
)
def test_bad_faces_raise_clear_error(faces, message):
    p = square_pts()
    keep = p.copy()
    with pytest.raises(ValueError, match=message):
        untangle_and_smooth(p, faces)
    assert np.array_equal(p, keep)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_or_inf_coordinates_raise_clear_error(bad):
    p = square_pts()
    p[4, 1] = bad
    keep = p.copy()
    with pytest.raises(ValueError, match="node 4 has a NaN or infinite coordinate"):
        untangle_and_smooth(p, FAN)
    assert np.array_equal(p, keep, equal_nan=True)



def _complex_calls():
    """(name, call with one complex array at the core's input) for every entry point."""
    from core import EEGTParams, PlaneFrame, mesh_stats, quality, summaries
    from core.metrics.reference_shapes import reference_targets, reference_to_2d

    p = square_pts()
    z = p + 0.5j  # every imaginary part nonzero: a cast would silently drop them
    z3 = np.column_stack([z, np.zeros(5)])
    ref = EEGTParams(target="reference")
    n_corners = 12
    return {
        "untangle_and_smooth points": lambda: untangle_and_smooth(z, FAN),
        "untangle_and_smooth_3d points": lambda: untangle_and_smooth_3d(z3, FAN),
        "quality points": lambda: quality(z, FAN),
        "quality points (a list)": lambda: quality(z.tolist(), FAN),
        "mesh_stats points": lambda: mesh_stats(z.astype(np.complex64), FAN),
        "summaries points": lambda: summaries(z, FAN),
        "PlaneFrame.fit points": lambda: PlaneFrame.fit(z3, FAN),
        "targets": lambda: quality(p, FAN, targets=np.ones((n_corners, 2)) * 1j),
        "reference_points": lambda: untangle_and_smooth(p, FAN, params=ref,
                                                        reference_points=z),
        "reference_targets": lambda: reference_targets(z, FAN, 5),
        "reference_to_2d": lambda: reference_to_2d(z3, FAN, 5),
    }


@pytest.mark.parametrize("name", list(_complex_calls()))
def test_complex_coordinates_raise_clear_error(name):
    """Regression: complex arrays lost their imaginary parts with only a ComplexWarning
    (a reference mesh's shapes, then, silently wrong). Now a one-line ValueError."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=r"complex numbers .*the imaginary parts would "
                                             r"be lost") as err:
            _complex_calls()[name]()
    assert "\n" not in str(err.value)


def test_all_nodes_fixed_raises_clear_error():
    p = square_pts()
    with pytest.raises(ValueError, match="every node is fixed"):
        untangle_and_smooth(p, FAN, fixed=np.array([False, False, False, False, True]))
    with pytest.raises(ValueError, match="every node is fixed"):
        untangle_and_smooth(p[:4], [[0, 1, 2, 3]])


def test_wrong_shapes_raise_clear_error():
    with pytest.raises(ValueError, match=r"points must be an \(N, 2\) array"):
        untangle_and_smooth(np.zeros((5, 3)), FAN)
    with pytest.raises(ValueError, match=r"fixed must be an \(5,\) bool array"):
        untangle_and_smooth(square_pts(), FAN, fixed=np.zeros(3, bool))
    with pytest.raises(ValueError, match="unknown backend"):
        untangle_and_smooth(square_pts(), FAN, backend="cuda")


def test_invalid_parameters_raise_clear_error():
    from core import EEGTParams

    with pytest.raises(ValueError, match="a must be > 0"):
        EEGTParams(a=0)
    with pytest.raises(ValueError, match="distance_refresh must be >= 1"):
        EEGTParams(distance_refresh=0)


def test_non_planar_3d_input_is_refused_and_untouched():
    v, f = load("tilted_plane")
    v = v.copy()
    v[40] += (
        0.05
        * np.cross(v[1] - v[0], v[2] - v[0])
        / np.linalg.norm(np.cross(v[1] - v[0], v[2] - v[0]))
    )
    keep = v.copy()
    with pytest.raises(ValueError, match="mesh is not planar: node 40"):
        untangle_and_smooth_3d(v, f)
    assert np.array_equal(v, keep)
    frame = PlaneFrame.fit(v, f, project=True)  # the user may ask to project instead
    assert frame.max_offset > 0.01


def test_zero_area_mesh_is_refused():
    p3 = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]], float)
    with pytest.raises(ValueError, match="zero total area"):
        PlaneFrame.fit(p3, [[0, 1, 2], [1, 3, 2]])


def test_non_manifold_edges_are_pinned_not_refused():
    p, f = load2d("quad_hole")
    faces = f.to_lists()
    a, b = faces[60][0], faces[60][1]  # an interior edge gets a third face
    p2 = np.vstack([p, [p[a] + [0.01, 0.02]]])
    faces2 = [*faces, [a, b, len(p)]]
    res = untangle_and_smooth(p2, faces2)
    assert not res.moved[a] and not res.moved[b]
    assert res.points[a].tolist() == p2[a].tolist()
