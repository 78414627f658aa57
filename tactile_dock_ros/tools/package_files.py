"""Input files of the tools named relative to the source tree (``--config config/robot.yaml``).

Decision: a path that exists is used as given. A relative path that does not exist from the
working directory is looked up in the installed package share
(``ament_index_python.packages.get_package_share_directory("tactile_dock_ros") / path``: a colcon
workspace or ROS install, where the docs' ``config/...`` paths are not under the working
directory), then in the source tree when the tools run from a checkout. The file used is logged
(stderr, stdout stays the tool's output); when none exists, the error names every place looked
at. Only for input files: output paths are never redirected into the share.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

PACKAGE = "tactile_dock_ros"
SOURCE_ROOT = Path(__file__).resolve().parents[2]  # a checkout: package.xml, config/, launch/


def _stderr(text: str) -> None:
    print(text, file=sys.stderr)


def installed_share() -> Path | None:
    """The package's installed share directory; None when the ament index has no such package
    (not installed, or ``AMENT_PREFIX_PATH`` unset)."""
    try:
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory(PACKAGE))
    except (ImportError, LookupError, OSError):  # PackageNotFoundError is a KeyError
        return None


def places(path: Path | str) -> list[Path]:
    """Where ``path`` is looked for, in order: as given, then (relative paths only) the
    installed share and the source tree of a checkout."""
    path = Path(path)
    found = [path]
    if not path.is_absolute():
        share = installed_share()
        if share is not None:
            found.append(share / path)
        if (SOURCE_ROOT / "package.xml").is_file():
            found.append(SOURCE_ROOT / path)
    return list(dict.fromkeys(found))


def resolve(path: Path | str, log: Callable[[str], None] | None = _stderr) -> Path:
    """The first of ``places(path)`` that is a file, logged with ``log`` (None: silent).

    Raises FileNotFoundError naming every place looked at."""
    candidates = places(path)
    for place in candidates:
        if place.is_file():
            if log is not None:
                where = "" if place == candidates[0] else f" ({path} is not in {Path.cwd()})"
                log(f"using {place.resolve()}{where}")
            return place
    looked = ", ".join(str(p if p.is_absolute() else Path.cwd() / p) for p in candidates)
    share = "" if installed_share() is not None else f"; no installed {PACKAGE} share found"
    raise FileNotFoundError(f"{path}: no such file (looked at {looked}{share})")
