"""The house rules, checked: layers, no import cycles, module sizes, the README's layout.

Layers, bottom up (README "Layout"): core, frames, ingest, math | sim, pipeline, report,
cli.  A module imports only its own layer and those listed for it below; math never
reads files (no ingest), the pipeline never renders (no report).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from conftest import REPO

PKG = REPO / "dracc"

#: each layer and the layers it may import (besides itself)
ALLOWED: dict[str, set[str]] = {
    "core": set(),
    "frames": {"core"},
    "ingest": {"core", "frames"},
    "math": {"core", "frames"},
    "sim": {"core", "frames", "ingest"},
    "pipeline": {"core", "frames", "ingest", "math"},
    "report": {"core", "frames", "ingest", "math", "pipeline"},
    "cli": {"core", "frames", "ingest", "math", "sim", "pipeline", "report"},
}
MAX_MODULE_LINES = 800
MAX_CLI_LINES = 1700  #: eleven commands and their shared options (was 1600 before issue 21)
MAX_COMMAND_LINES = 250


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PKG.rglob("*.py")):
        parts = list(path.relative_to(REPO).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()
#: compiled extensions (``dracc/ingest/_nmeascan.c``): modules too, with no Python imports
EXTENSIONS = {".".join(p.relative_to(REPO).with_suffix("").parts) for p in PKG.rglob("*.c")}


def _layer(module: str) -> str | None:
    parts = module.split(".")
    if len(parts) == 1 or parts[1] == "__main__":  # the root: __version__; python -m dracc
        return None if parts[-1] == "dracc" else "cli"
    return parts[1]


def _imports(module: str, path: Path) -> set[str]:
    """dracc modules ``module`` imports (at any depth of its code), resolved to modules."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.split(".")[0] == "dracc")
        elif isinstance(node, ast.ImportFrom) and node.module:
            assert node.level == 0, f"{module}: relative import (the house uses absolute ones)"
            if node.module.split(".")[0] != "dracc":
                continue
            # ``from pkg import sub`` depends on the submodule; any other name on ``pkg``
            subs = [f"{node.module}.{a.name}" for a in node.names]
            found.update(s for s in subs if s in MODULES)
            if any(s not in MODULES and s not in EXTENSIONS for s in subs):
                found.add(node.module)
    return {m for m in found if m != module}


GRAPH = {m: _imports(m, p) for m, p in MODULES.items()}


def test_every_module_has_a_layer():
    layers = {_layer(m) for m in MODULES} - {None}
    assert layers <= set(ALLOWED), layers - set(ALLOWED)


def test_no_import_runs_back_up_the_layers():
    wrong = []
    for m, deps in GRAPH.items():
        mine = _layer(m)
        if mine is None:
            assert not deps, f"dracc/__init__.py imports {deps}: it holds the version only"
            continue
        for d in deps:
            theirs = _layer(d)
            if theirs is not None and theirs != mine and theirs not in ALLOWED[mine]:
                wrong.append(f"{m} ({mine}) imports {d} ({theirs})")
    assert not wrong, "\n".join(wrong)


def test_no_import_cycles():
    # Tarjan's strongly connected components over the import graph
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in GRAPH.get(v, ()):
            if w not in GRAPH:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in GRAPH:
        if v not in index:
            visit(v)
    assert not cycles, cycles


def _lines(path: Path) -> int:
    return len(path.read_text(encoding="utf-8").splitlines())


def test_no_module_over_the_limit():
    big = {str(p.relative_to(REPO)): _lines(p) for p in MODULES.values()}
    assert not {k: v for k, v in big.items() if v > MAX_MODULE_LINES}


def test_the_cli_is_thin():
    files = sorted((PKG / "cli").glob("*.py"))
    sizes = {p.name: _lines(p) for p in files}
    assert sum(sizes.values()) <= MAX_CLI_LINES, sizes
    assert not {k: v for k, v in sizes.items() if v > MAX_COMMAND_LINES}


def _layout_section() -> str:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    m = re.search(r"^## Layout\n(.*?)(?=^## |\Z)", text, re.S | re.M)
    assert m, "README has a '## Layout' section"
    return m.group(1)


def test_readme_layout_matches_the_tree():
    section = _layout_section()
    named = set(re.findall(r"\bdracc/[\w/]*[\w]+(?:\.py)?/?", section))
    for name in named:
        assert (REPO / name).exists(), f"README layout names {name}, which does not exist"
    packages = sorted(p.parent for p in PKG.rglob("__init__.py") if p.parent != PKG)
    missing = [str(p.relative_to(REPO)) for p in packages if f" {p.name}/" not in section]
    assert not missing, f"packages the README layout does not show: {missing}"
    modules = [p.relative_to(PKG).as_posix() for p in PKG.rglob("*.py")]
    for mod in modules:
        leaf = Path(mod)
        if leaf.name.startswith("__"):
            continue
        shown = leaf.name in section or leaf.stem in section
        assert shown, f"README layout does not mention dracc/{mod}"


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_each_layer_exists(layer):
    assert any(_layer(m) == layer for m in MODULES)
