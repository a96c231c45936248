"""LeRobot's dataset loader (``lerobot.datasets.lerobot_dataset.LeRobotDataset``) as the tests import it.

The test extra installs LeRobot's datasets part without the rest (pyproject.toml): torch is its CPU build, the one
the registries carry, and the registries' torchvision wheels are CUDA builds whose compiled operators cannot load
against it. ``lerobot.datasets.utils`` imports ``torchvision.transforms`` when it is imported, and uses it only to
transform images, which the sensor's features are not. So where torchvision cannot be imported, :func:`install`
puts in its place an empty module that says so (no transform in it): LeRobot's own code then reads and writes the
datasets, and a test that touched an image transform would fail on the missing name, not pass on a fake one.
Where a working torchvision is installed, nothing is replaced."""

from __future__ import annotations

import importlib.machinery
import sys
import types


def install() -> None:
    try:
        import torchvision  # noqa: F401 - whether it loads is the question
    except Exception:  # ImportError, or RuntimeError or OSError from a build it cannot load
        for name in [m for m in sys.modules if m == "torchvision" or m.startswith("torchvision.")]:
            del sys.modules[name]
        for name in ("torchvision", "torchvision.transforms", "torchvision.transforms.v2"):
            module = types.ModuleType(name, "empty: torchvision cannot load here (tests/lerobot_loader.py)")
            module.__spec__ = importlib.machinery.ModuleSpec(name, None)
            sys.modules[name] = module
        sys.modules["torchvision"].transforms = sys.modules["torchvision.transforms"]  # type: ignore[attr-defined]
        sys.modules["torchvision.transforms"].v2 = sys.modules["torchvision.transforms.v2"]  # type: ignore[attr-defined]


def dataset_class():
    """``LeRobotDataset``, after :func:`install`."""
    install()
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    return LeRobotDataset
