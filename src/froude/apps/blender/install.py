"""Installing the add-on: a small Blender add-on package, ``froude_blender``, that registers
``froude.apps.blender.addon`` from the froude installed in Blender's Python.

Blender lists add-ons from its user folder (``scripts/addons``) or installs them from a zip (Edit >
Preferences > Add-ons > Install from Disk). The add-on itself is a few lines: everything else is the
froude package, which Blender's Python must have (README: one command).
"""
from __future__ import annotations

import os
import platform
import re
import zipfile
from pathlib import Path

from ... import __version__
from ...errors import FroudeError
from ...io.atomic import atomic_write, atomic_write_text

#: The add-on's module name in Blender.
ADDON_NAME = "froude_blender"
#: The one command that installs froude into Blender's own Python (README).
PIP_INTO_BLENDER = ('blender --background --python-expr "import subprocess, sys; '
                    "subprocess.check_call([sys.executable, '-m', 'pip', 'install', 'froude[gltf]'])\"")


def addon_source() -> str:
    """The add-on's ``__init__.py``."""
    major, minor, patch = (int(x) for x in re.findall(r"\d+", __version__)[:3])
    return f'''"""froude in Blender: rescale the active armature's action physically (3D View > Sidebar > froude).

Written by `froude blender --install-addon` (froude {__version__}); the add-on is froude.apps.blender.addon
from the froude installed in Blender's Python.
"""
bl_info = {{
    "name": "froude",
    "author": "froude",
    "version": ({major}, {minor}, {patch}),
    "blender": (4, 2, 0),
    "location": "3D View > Sidebar > froude",
    "description": "Physically based rescaling of running and walking (after Pollard 1999): new characters, "
                   "speeds and accelerations as new actions",
    "category": "Animation",
}}


def _addon():
    try:
        from froude.apps.blender import addon
    except ImportError as e:
        raise ImportError("froude is not installed in Blender's Python ({{}}); install it with: "
                          {PIP_INTO_BLENDER!r}.format(e)) from None
    return addon


def register():
    _addon().register()


def unregister():
    _addon().unregister()
'''


def user_addon_dirs() -> list[Path]:
    """Blender's user add-on folders on this machine (``<config>/<version>/scripts/addons``), newest first."""
    home = Path.home()
    system = platform.system()
    if system == "Windows":
        base = Path(os.environ.get("APPDATA", home / "AppData" / "Roaming")) / "Blender Foundation" / "Blender"
    elif system == "Darwin":
        base = home / "Library" / "Application Support" / "Blender"
    else:
        base = Path(os.environ.get("XDG_CONFIG_HOME", home / ".config")) / "blender"
    versions = [p for p in base.glob("*") if p.is_dir() and re.fullmatch(r"\d+\.\d+", p.name)]
    versions.sort(key=lambda p: tuple(int(x) for x in p.name.split(".")), reverse=True)
    return [v / "scripts" / "addons" for v in versions]


def install_addon(addons_dir: str | os.PathLike | None = None) -> Path:
    """Write the add-on into ``addons_dir`` (default: the newest Blender's user add-on folder); returns the
    add-on's ``__init__.py``. Raises FroudeError (one line) when there is no such folder."""
    if addons_dir is None:
        found = user_addon_dirs()
        if not found:
            raise FroudeError("no Blender user folder found (Blender's config folder has no version folder): "
                              "start Blender once, or pass --addons-dir, or use --zip and install the zip from "
                              "Blender's preferences")
        addons_dir = found[0]
    target = Path(addons_dir) / ADDON_NAME
    try:
        target.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise FroudeError(f"{target}: cannot create the add-on folder: {e.strerror}") from None
    init = target / "__init__.py"
    atomic_write_text(init, addon_source())
    return init


def addon_zip(path: str | os.PathLike) -> Path:
    """Write the add-on as a zip for Blender's Install from Disk; returns the path."""

    def write(tmp: str) -> None:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr(f"{ADDON_NAME}/__init__.py", addon_source())

    return atomic_write(path, write)
