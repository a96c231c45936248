"""magfab: one design spec in, everything a lab needs to make a soft magnetic tri-axis tactile sensor out.

The public API is a pipeline of pure functions::

    spec = load_spec("spec.toml")      # validated, frozen Spec (None: the embedded MagOne design)
    design = derive(spec)              # every derived dimension, in one place
    result = build(spec, out_dir)      # solids, meshes, checks, files written atomically
"""

__version__ = "0.1.0"

from .build import BuildResult, build, plan  # noqa: E402
from .design import Design, derive  # noqa: E402
from .errors import BuildError, Finding, Severity, SpecError  # noqa: E402
from .spec import Spec, load_spec, parse_spec  # noqa: E402

__all__ = [
    "__version__",
    "BuildError",
    "BuildResult",
    "Design",
    "Finding",
    "Severity",
    "Spec",
    "SpecError",
    "build",
    "derive",
    "load_spec",
    "parse_spec",
    "plan",
]
