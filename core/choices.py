"""Every choice list and parameter bound, defined once.

The core validates with these (``EEGTParams``, the backend and UV scope checks); the
Blender properties, the add-on preferences, the UV settings and the command's argument
parser derive their items, limits and ``choices=`` from them. Each choice has an id (the
core's value), a label and a description; a Blender enum's identifiers are the ids (upper
case for the backend and the UV scope).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["BACKEND", "BOUNDARY", "DEVICE_GLOBAL_STAGE", "HYBRID", "NUMPY_ENGINE",
           "OPENCL_ENGINE", "PARAMETERS", "REGION", "SCALING", "SMALL_ON_GPU", "TARGET", "UNTANGLE",
           "UV_SCOPE", "UV_TARGET", "Bound", "Choice", "Enumeration", "global_stage_on_device",
           "ids", "violation"]


@dataclass(frozen=True)
class Choice:
    """One value of an enumeration."""

    id: str
    label: str
    description: str


Enumeration = tuple[Choice, ...]


def ids(choices: Enumeration) -> tuple[str, ...]:
    """The ids of an enumeration, in order."""
    return tuple(c.id for c in choices)


@dataclass(frozen=True)
class Bound:
    """The valid range of a numeric parameter: ``low`` (excluded when ``low_open``) up to
    ``high`` (None: unbounded); ``ui_min`` is a user interface's least value where ``low``
    itself is excluded, ``soft_max`` the end of its slider."""

    low: float
    low_open: bool = False
    high: float | None = None
    unit: str = ""
    ui_min: float | None = None
    soft_max: float | None = None

    def violation(self, name: str, value: float) -> str | None:
        """Why ``value`` is out of range (one line naming ``name``), or None."""
        if self.high is not None:
            if not self.low <= value <= self.high:
                return f"{name} must be in [{self.low:g}, {self.high:g}]{self.unit}"
            return None
        if self.low_open:
            return None if value > self.low else f"{name} must be > {self.low:g}"
        return None if value >= self.low else f"{name} must be >= {self.low:g}"


UNTANGLE: Enumeration = (
    Choice("auto", "Auto", "Global under 20 000 faces, else EEGT + Local"),
    Choice("global", "Global", "Foldover-free optimization of the whole mesh removes inverted "
           "faces (most robust)"),
    Choice("eegt+local", "EEGT + Local", "EEGT while it makes progress, the optimization only "
           "around the folds it leaves (large meshes: fastest)"),
    Choice("eegt+global", "EEGT + Global", "EEGT first, the optimization when EEGT stalls"),
    Choice("eegt", "EEGT Only", "The paper's EEGT untangling only"),
)

SCALING: Enumeration = (
    Choice("edge", "Edge", "Shrink keeps the mean edge length (paper)"),
    Choice("area", "Area", "Shrink keeps the mean area"),
)

BOUNDARY: Enumeration = (
    Choice("fixed", "Fixed", "Boundary vertices stay where they are (paper)"),
    Choice("slide", "Slide", "Boundary vertices slide along the input boundary and never leave "
           "it; corners sharper than the Feature Angle, pinned and non-manifold vertices stay"),
    Choice("free", "Free", "Boundary vertices move freely; only pinned and non-manifold "
           "vertices stay"),
)

TARGET: Enumeration = (
    Choice("regular", "Regular", "Pull every face towards the regular polygon (paper)"),
    Choice("reference", "Reference", "Pull every face towards its own shape in a reference of "
           "the same topology (a shape key or an object): keeps grading and anisotropy"),
    Choice("keep", "Keep Shapes", "Pull every face towards its own shape as given: grading, "
           "anisotropy and sizes stay; a folded face takes its shape from the reference when "
           "one is given, else from its valid neighbours"),
)

REGION: Enumeration = (
    Choice("mesh", "Whole Mesh", "Every free vertex may move (paper)"),
    Choice("folds", "Folds Only", "Only the folded faces and a margin around them, grown while "
           "the fold cannot be opened inside it: every other vertex keeps its bits (a repair)"),
)

# Compute backends. A run reports the engine it used (``backends.make_engine``), which is
# not one of these ids.
BACKEND: Enumeration = (
    Choice("numpy", "NumPy", "Reference CPU backend (always available)"),
    Choice("opencl", "OpenCL", "OpenCL device (NumPy when pyopencl or a device is missing)"),
    Choice("auto", "Auto", "OpenCL where it is faster (small meshes: its global stage only), "
           "else NumPy"),
)
# The engines a run reports (``backends.make_engine``), and which of them solve the global
# stage on the OpenCL device: a fixed set of names, never a prefix of a label.
NUMPY_ENGINE = "numpy"
OPENCL_ENGINE = "opencl"  # ``engine_opencl.OpenCLEngine.name``
HYBRID = "opencl (global stage) + numpy (EEGT steps, small mesh)"
SMALL_ON_GPU = "numpy (auto: a small mesh; a GPU's set-up costs more than it saves)"
DEVICE_GLOBAL_STAGE = frozenset({OPENCL_ENGINE, HYBRID})


def global_stage_on_device(engine: str) -> bool:
    """Whether a run on the engine named ``engine`` solves its global stage on the OpenCL
    device (the OpenCL engine, or NumPy's EEGT steps beside the device's global stage)."""
    return engine in DEVICE_GLOBAL_STAGE


# Which faces of a UV run move (``uv_untangle.untangle_uv``).
UV_SCOPE: Enumeration = (
    Choice("tangles", "Around Tangles", "In an island with flipped, inverted or overlapping "
           "faces only those and the faces around them move (more around them until they "
           "untangle); an island without any is smoothed as a whole"),
    Choice("selection", "Whole Selection", "Every selected face moves (untangled and smoothed)"),
)

# The shape each UV face is pulled towards.
UV_TARGET: Enumeration = (
    Choice("3D", "3D Faces", "Pull each UV face towards its own 3D face's shape (untangling "
           "also lowers stretch); distortion 1 = similar to the 3D face"),
    Choice("REGULAR", "Regular", "Pull each UV face towards the regular polygon (the paper's "
           "EEGT)"),
    Choice("KEEP", "Keep Shapes", "Pull each UV face towards its own shape as laid out (a "
           "repair keeps the layout's grading and stretch); a folded face takes a neighbour's "
           "shape, else its 3D face's. With Around Tangles only the tangles and a margin move"),
)

# Every checked EEGTParams field, in the order the checks run (the first failure is
# reported): a numeric field's bound, or a string field's enumeration.
PARAMETERS: dict[str, Bound | Enumeration] = {
    "a": Bound(0.0, low_open=True, ui_min=1e-6, soft_max=1.0),
    "eta": Bound(0.0, soft_max=8.0),
    "c": Bound(0.0, soft_max=8.0),
    "inverted_weight": Bound(0.0, low_open=True, ui_min=1e-6, soft_max=50.0),
    "tol": Bound(0.0, soft_max=0.1),
    "tol_min": Bound(0.0, soft_max=0.1),
    "max_untangle_iterations": Bound(0, soft_max=20000),
    "max_smooth_iterations": Bound(0, soft_max=5000),
    "distance_refresh": Bound(1, soft_max=100),
    "scaling": SCALING,
    "stall_iterations": Bound(1, soft_max=1000),
    "untangle": UNTANGLE,
    "polish_iterations": Bound(0, soft_max=5000),
    "lift_rounds": Bound(0),
    "boundary": BOUNDARY,
    "feature_angle": Bound(0.0, high=180.0, unit=" degrees", soft_max=180.0),
    "target": TARGET,
    "region": REGION,
}


def violation(name: str, value: object) -> str | None:
    """Why ``value`` is not valid for parameter ``name`` (one line), or None."""
    rule = PARAMETERS[name]
    if isinstance(rule, Bound):
        return rule.violation(name, value)  # type: ignore[arg-type]
    if value in ids(rule):
        return None
    return f"{name} must be one of {', '.join(ids(rule))}"
