"""The layers hold (issue 27): no import circle between froude's modules and no import up a layer, counting
imports inside functions, and every import of froude inside a function says why (``# lazy: <why>``: only to
keep start-up fast). The parse and the layer order are ``scripts/layers.py``'s (the same that draws
docs/architecture.md's picture); run it to see the graph and every violation as file:line.
"""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import layers  # noqa: E402

#: Upward imports left to remove, each with what removes it. The test fails on any other upward import, and on
#: an entry here that no longer happens (take it off): the list may only shrink.
KNOWN_UPWARD: dict[tuple[str, str], str] = {}
#: Imports of froude inside functions without a '# lazy:' reason (scripts/layers.py lists them as file:line): none.
#: A new one goes to the top of its module or says how it keeps start-up fast.
MAX_UNMARKED_LAZY = 0


@pytest.fixture(scope="module")
def imports():
    return layers.all_imports()


def test_every_module_has_a_layer(imports):
    """A new package or top-level module is placed in a layer (scripts/layers.py PLACES) before it is used."""
    for name in layers.modules():
        assert layers.layer_of(name) in layers.ORDER


def test_no_import_circle(imports):
    """No circle between modules, imports inside functions counted (TYPE_CHECKING imports never run)."""
    found = layers.circles(imports)
    assert not found, "\n".join(found)


def test_no_new_upward_import(imports):
    """No import up a layer except the known ones, which must still happen (then take them off the list)."""
    up = {(i.source, i.target): i.where for i in imports
          if layers.ORDER[layers.layer_of(i.target)] > layers.ORDER[layers.layer_of(i.source)]}
    new = [f"{where}: {src} ({layers.layer_of(src)}) imports {dst} ({layers.layer_of(dst)})"
           for (src, dst), where in sorted(up.items()) if (src, dst) not in KNOWN_UPWARD]
    assert not new, "imports up a layer (move the code to its layer or pass a value):\n" + "\n".join(new)
    stale = sorted(set(KNOWN_UPWARD) - set(up))
    assert not stale, f"listed as known upward imports but gone (take them off KNOWN_UPWARD): {stale}"


def test_imports_inside_functions_say_why(imports):
    """An import of froude inside a function carries '# lazy: <why>' (on its line or the one above); the
    ones not yet marked may only become fewer."""
    unmarked = layers.unmarked_lazy(imports)
    assert len(unmarked) <= MAX_UNMARKED_LAZY, (
        f"{len(unmarked)} imports inside functions without '{layers.LAZY_MARK} <why>', more than the "
        f"{MAX_UNMARKED_LAZY} left to do: move the new one to the top of its module or say why:\n"
        + "\n".join(unmarked))


def test_the_checks_catch_what_they_should(tmp_path):
    """The parse finds a circle through an import inside a function, an upward import at file:line, a
    relative ``from . import x``, and a mark."""
    pkg = tmp_path / "froude"
    (pkg / "core").mkdir(parents=True)
    (pkg / "io").mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "core" / "__init__.py").write_text("")
    (pkg / "io" / "__init__.py").write_text("")
    (pkg / "core" / "a.py").write_text("from . import b\n")
    (pkg / "core" / "b.py").write_text("def f():\n    from .a import x  # lazy: start-up\n\n\n"
                                       "def g():\n    from ..io import c\n")
    (pkg / "io" / "c.py").write_text("import froude.core.a\n")
    found = layers.all_imports(pkg)
    pairs = {(i.source, i.target, i.line, i.in_function, i.marked) for i in found}
    assert ("froude.core.a", "froude.core.b", 1, False, False) in pairs
    assert ("froude.core.b", "froude.core.a", 2, True, True) in pairs
    assert ("froude.core.b", "froude.io.c", 6, True, False) in pairs
    assert any("froude.core.a" in c and "froude.core.b" in c for c in layers.circles(found))
    assert [u.split(": ", 1)[1] for u in layers.upward(found)] == [
        "froude.core.b (core) imports froude.io.c (io)"]
    assert len(layers.unmarked_lazy(found)) == 1
