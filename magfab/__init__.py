"""magfab: one design spec in, everything a lab needs to make a soft magnetic tri-axis tactile sensor out.

The public API is a pipeline of pure functions::

    spec = load_spec("spec.toml")      # validated, frozen Spec (None: the embedded MagOne design)
    design = derive(spec)              # every derived dimension, in one place
    result = build(spec, out_dir)      # solids, meshes, checks, files written atomically

The names are loaded on first use, so ``import magfab`` (and ``magfab --help``) cost almost nothing.
"""

from importlib import import_module

__version__ = "0.1.0"

_API = {
    "BuildError": "errors", "Finding": "errors", "Severity": "errors", "SpecError": "errors",
    "Spec": "spec", "load_spec": "spec", "parse_spec": "spec",
    "Design": "design", "derive": "design",
    "BuildResult": "pipeline", "build": "pipeline", "plan": "pipeline",
}

__all__ = ["__version__", *sorted(_API)]


def __getattr__(name: str) -> object:
    if name not in _API:
        raise AttributeError(f"module 'magfab' has no attribute {name!r}")
    value = getattr(import_module(f".{_API[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
