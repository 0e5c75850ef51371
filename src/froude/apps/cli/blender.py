"""``froude blender``: install the Blender add-on (a panel in the 3D view's sidebar that rescales the active
armature's action), or write it as a zip for Blender's Install from Disk."""
from __future__ import annotations

from .common import say

#: The one-line summary ``froude --help`` lists.
HELP = "install the Blender add-on (3D View > Sidebar > froude), or write it as a zip"


def register(sub) -> None:
    p = sub.add_parser(
        "blender", help=HELP,
        description="The froude add-on for Blender 4.2 and later: a 'froude' tab in the 3D view's sidebar that "
        "analyses the active armature's action (froude info) and rescales it (froude scale, froude accelerate) "
        "into a new action on the same armature. The add-on runs the froude installed in Blender's own Python: "
        "install it there first (README, 'froude in Blender').",
        epilog="Examples: froude blender --install-addon ; froude blender --zip froude_blender.zip",
    )
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--install-addon", action="store_true",
                      help="write the add-on into Blender's user add-on folder (the newest Blender version found, "
                      "or --addons-dir); then enable 'froude' in Edit > Preferences > Add-ons")
    what.add_argument("--zip", metavar="OUT.zip", help="write the add-on as a zip (Preferences > Add-ons > Install "
                      "from Disk)")
    p.add_argument("--addons-dir", metavar="DIR", help="with --install-addon: the add-on folder to write into")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    p.set_defaults(func=run)


def run(args) -> int:
    from ...errors import FroudeError  # lazy: start-up (froude --help imports every verb module and no NumPy)
    from ...io.atomic import require_suffix  # lazy: start-up (froude --help imports every verb module and no NumPy)
    from ..blender.install import PIP_INTO_BLENDER, addon_zip, install_addon  # lazy: start-up

    if args.addons_dir and not args.install_addon:
        raise FroudeError("--addons-dir goes with --install-addon")
    if args.zip:
        out = addon_zip(require_suffix(args.zip, (".zip",)))
        say(f"wrote {out}: in Blender, Edit > Preferences > Add-ons > Install from Disk, then enable 'froude'",
            args.quiet)
    else:
        init = install_addon(args.addons_dir)
        say(f"wrote {init.parent}: in Blender, enable 'froude' in Edit > Preferences > Add-ons", args.quiet)
    say(f"the add-on needs froude in Blender's Python; if it is not there: {PIP_INTO_BLENDER}", args.quiet)
    return 0
