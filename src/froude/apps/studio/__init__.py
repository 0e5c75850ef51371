"""``froude view``: the live studio in the browser (viser, the optional extra ``froude[studio]``).

    from froude import pipeline
    from froude.apps.studio import serve
    serve(pipeline.prepare("run.bvh"), port=8080)      # blocks until Ctrl-C

``tracks`` (what is drawn, NumPy only) and ``session`` (parameters → pipeline results, no UI) import
without viser; ``app`` imports viser when a ``Studio`` is built.
"""
from __future__ import annotations

from .session import Params, Session

__all__ = ["Params", "Session", "Studio", "serve"]


def __getattr__(name):  # viser only when the UI is wanted
    if name in ("Studio", "serve"):
        from . import app  # lazy: start-up (viser only when the UI is wanted)

        return getattr(app, name)
    raise AttributeError(name)
