"""EEGT parameters: the paper's values and our defaults (their bounds and choice lists:
``choices``)."""

from __future__ import annotations

import math
from dataclasses import MISSING, asdict, dataclass, field, fields, replace
from numbers import Integral, Real
from typing import Any

from .choices import BOUNDARY, PARAMETERS, TARGET, UNTANGLE, ids, violation

__all__ = ["BOUNDARY_MODES", "TARGETS", "UNTANGLE_METHODS", "EEGTParams"]

UNTANGLE_METHODS = ids(UNTANGLE)
BOUNDARY_MODES = ids(BOUNDARY)  # core.eegt.boundary
TARGETS = ids(TARGET)


def _plain(value: Any) -> Any:
    """A NumPy scalar as its Python number (a message reads alike under NumPy 1 and 2, whose
    repr says "np.float64(2.5)"); anything else as it is."""
    return value.item() if hasattr(value, "dtype") and hasattr(value, "item") else value


@dataclass(frozen=True)
class EEGTParams:
    """Every knob of the method; field metadata gives a label and help for UIs and CLIs."""

    a: float = field(
        default=0.2, metadata={"help": "lambda = a (1 - q) per element (paper eq. 17)."}
    )
    eta: float = field(
        default=2.0, metadata={"help": "Quality weight exponent: g = (1 - q)^eta (eq. 21)."}
    )
    c: float = field(
        default=2.0, metadata={"help": "Distance weight exponent: f = (lbar / d)^c (eq. 20)."}
    )
    inverted_weight: float = field(
        default=5.0, metadata={"help": "Quality weight g of an inverted element (eq. 21)."}
    )
    tol: float = field(
        default=1e-3,
        metadata={"help": "Smoothing stops when the mean quality improves by less than this."},
    )
    tol_min: float = field(
        default=1e-3,
        metadata={
            "help": "Smoothing also goes on while the worst face quality improves by at least "
            "this and the mean does not fall (0: the paper's rule, the mean only)"
        },
    )
    max_untangle_iterations: int = field(
        default=20000, metadata={"help": "Untangling gives up after this many iterations "
                                 "(the optimizer: per attempt, more on a wide mesh, in "
                                 "proportion to its width, up to half again while a fold "
                                 "closes in; a run still tangled is tried once "
                                 "more from its other start, the input or the harmonic map)."}
    )
    max_smooth_iterations: int = field(
        default=1000, metadata={"help": "Smoothing stops after this many iterations."}
    )
    distance_refresh: int = field(
        default=10,
        metadata={"help": "Refresh element-to-boundary distances every this many iterations."},
    )
    untangle: str = field(
        default="auto",
        metadata={
            "help": "How inverted faces are removed: 'auto' ('global' under 20 000 faces, "
            "else 'eegt+local'), 'global' foldover-free optimization of the whole mesh, "
            "'eegt+local' EEGT while it makes progress, the optimization only around what it "
            "leaves, 'eegt+global' EEGT first and the optimization of the whole mesh when it "
            "stalls, 'eegt' EEGT only (the paper)"
        },
    )
    stall_iterations: int = field(
        default=50,
        metadata={
            "help": "EEGT untangling counts as stalled when its inverted count has not "
            "reached a new low for this many iterations"
        },
    )
    polish_iterations: int = field(
        default=300,
        metadata={
            "help": "Optimization iterations that improve shape quality once valid, "
            "before EEGT smoothing ('eegt+local': the whole-mesh run that maximises the mean "
            "quality; 0: none; beyond the paper)"
        },
    )
    lift_rounds: int = field(
        default=10,
        metadata={
            "help": "Rounds that raise the worst face quality after the optimization without "
            "lowering the mean quality below its result or more than 3 percent below the best "
            "mean reached (0: none; beyond the paper)"
        },
    )
    scaling: str = field(
        default="edge",
        metadata={
            "help": "Shrink step: 'edge' keeps the mean edge length (paper), 'area' the area."
        },
    )
    boundary: str = field(
        default="fixed",
        metadata={
            "help": "Boundary vertices: 'fixed' stay (paper), 'slide' move along the input "
            "boundary curve (corners sharper than the feature angle, pinned and non-manifold "
            "vertices stay), 'free' move freely (only pinned and non-manifold vertices stay)"
        },
    )
    feature_angle: float = field(
        default=30.0,
        metadata={
            "help": "Boundary 'slide': a boundary vertex whose boundary turns by more than "
            "this many degrees is a corner and stays"
        },
    )
    target: str = field(
        default="regular",
        metadata={
            "help": "Shape each face is pulled towards: 'regular' polygon (paper), its "
            "shape in a 'reference' mesh of the same topology (keeps grading and anisotropy), "
            "or its own shape as given, 'keep' (folded faces: the reference's shape when one "
            "is given, else their valid neighbours')"
        },
    )
    region: str = field(
        default="mesh",
        metadata={
            "help": "What may move: the whole 'mesh' (paper), or only the 'folds': the folded "
            "faces and a margin grown while the fold cannot be opened inside it (a repair: "
            "every other vertex keeps its bits)"
        },
    )

    def __post_init__(self) -> None:
        self._check_types()
        for name in PARAMETERS:
            message = violation(name, getattr(self, name))
            if message:
                raise ValueError(f"invalid parameter: {message}")

    def _check_types(self) -> None:
        """Each field has its default's type (an int field takes any integer, a float field
        any finite real); NaN and infinities are refused, since no knob means anything there."""
        for f in fields(self):
            value, default = getattr(self, f.name), f.default
            if default is MISSING:
                continue
            if isinstance(default, str):
                ok = isinstance(value, str)
                kind = "a string"
            elif isinstance(default, int):
                ok = isinstance(value, Integral) and not isinstance(value, bool)
                kind = "an integer"
            else:
                ok = isinstance(value, Real) and not isinstance(value, bool)
                kind = "a finite number"
                if ok and not math.isfinite(float(value)):
                    raise ValueError(f"invalid parameter: {f.name} must be finite, "
                                     f"got {_plain(value)!r}")
            if not ok:
                raise ValueError(f"invalid parameter: {f.name} must be {kind}, "
                                 f"got {_plain(value)!r}")

    @classmethod
    def paper(cls) -> EEGTParams:
        """Exactly the paper's settings (Section 3 and 4): a = 0.2, eta = c = 2, tol 1e-3."""
        return cls(
            a=0.2,
            eta=2.0,
            c=2.0,
            inverted_weight=5.0,
            tol=1e-3,
            tol_min=0.0,
            max_untangle_iterations=5000,
            max_smooth_iterations=1000,
            distance_refresh=1,
            scaling="edge",
            untangle="eegt",
            polish_iterations=0,
            lift_rounds=0,
        )

    def with_(self, **changes) -> EEGTParams:
        return replace(self, **changes)

    def as_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def field_names(cls) -> list[str]:
        return [f.name for f in fields(cls)]

    @classmethod
    def help(cls, name: str) -> str:
        """One-line description of a field, for tooltips and --help."""
        return {f.name: f.metadata.get("help", "") for f in fields(cls)}[name]
