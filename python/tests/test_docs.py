"""The documentation cannot rot: doctests pass, the stubs document everything, the API pages
cover the package, and the stubs' `Literal` options reject typos.

The site itself is built by `scripts/test.sh` (`mkdocs build --strict`); these tests need no
documentation tools.
"""

from __future__ import annotations

import ast
import doctest
import importlib
import pkgutil
import re
import types
from pathlib import Path

import pytest

import fuzzyq

ROOT = Path(__file__).resolve().parents[2]
STUB = ROOT / "python" / "fuzzyq" / "_fuzzyq.pyi"
SITE = ROOT / "docs" / "site"


def package_modules() -> list[str]:
    """The installed package's Python modules (the extension has no doctests to run)."""
    names = ["fuzzyq"]
    for info in pkgutil.walk_packages(fuzzyq.__path__, "fuzzyq."):
        if not info.name.rsplit(".", 1)[-1].startswith("_fuzzyq"):
            names.append(info.name)
    return names


@pytest.mark.parametrize("name", package_modules())
def test_doctests_pass(name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    if name.startswith("fuzzyq.envs"):
        pytest.importorskip("gymnasium")
        pytest.importorskip("pettingzoo")
    if name == "fuzzyq.plot":
        pytest.importorskip("matplotlib")
    monkeypatch.chdir(tmp_path)  # an example may write files
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS, verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} doctests of {name} failed"


def test_the_package_docstring_has_a_doctest() -> None:
    tests = doctest.DocTestFinder().find(fuzzyq)
    assert sum(len(t.examples) for t in tests) >= 3


# The stubs: every class, function, method and property has a docstring, and every function's
# parameters are explained in its "Args:" section (a constructor's, `__new__`, in the class's).


def _docstring_args(doc: str) -> set[str]:
    match = re.search(
        r"^\s*Args:\n(.*?)(?=^\s*(Returns|Raises|Example|Examples|Yields):|\Z)", doc, re.S | re.M
    )
    if match is None:
        return set()
    return set(re.findall(r"^\s{4,8}(\w+)(?: \([^)]*\))?:", match.group(1), re.M))


def _params(fn: ast.FunctionDef) -> list[str]:
    a = fn.args
    names = [p.arg for p in [*a.posonlyargs, *a.args, *a.kwonlyargs]]
    names += [p.arg for p in (a.vararg, a.kwarg) if p is not None]
    return [n for n in names if n not in ("self", "cls")]


def _decorators(fn: ast.FunctionDef) -> set[str]:
    return {d.id if isinstance(d, ast.Name) else getattr(d, "attr", "") for d in fn.decorator_list}


def _stub_problems() -> list[str]:
    tree = ast.parse(STUB.read_text())
    problems = []
    if not ast.get_docstring(tree):
        problems.append("the module has no docstring")

    def check_function(fn: ast.FunctionDef, owner: str, class_doc: str | None) -> None:
        where = f"{owner}{fn.name}"
        doc = ast.get_docstring(fn)
        decorators = _decorators(fn)
        if (
            "overload" in decorators
            and fn.body
            and isinstance(fn.body[0], ast.Expr)
            and doc is None
        ):
            return  # a further overload variant: the first one carries the docstring
        if doc is None:
            problems.append(f"{where} has no docstring")
            return
        if "property" in decorators:
            return
        documented = (
            _docstring_args(class_doc or "") if fn.name == "__new__" else _docstring_args(doc)
        )
        for p in _params(fn):
            if p not in documented:
                problems.append(f"{where}: parameter {p!r} is not explained under Args:")
        returns = fn.returns
        if (
            fn.name != "__new__"
            and not (isinstance(returns, ast.Constant) and returns.value is None)
            and "Returns:" not in doc
        ):
            problems.append(f"{where} has no Returns: section")

    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            class_doc = ast.get_docstring(node)
            if class_doc is None:
                problems.append(f"class {node.name} has no docstring")
            for item in node.body:
                if isinstance(item, ast.FunctionDef):
                    check_function(item, f"{node.name}.", class_doc)
        elif isinstance(node, ast.FunctionDef):
            check_function(node, "", None)
    return problems


def test_the_stubs_document_every_parameter() -> None:
    problems = _stub_problems()
    assert not problems, "\n".join(problems)


# The API pages: every `::: name` exists, and every public name is documented somewhere.


def _api_targets() -> set[str]:
    targets = set()
    for page in (SITE / "api").glob("*.md"):
        targets.update(re.findall(r"^::: ([\w.]+)", page.read_text(), re.M))
    return targets


def _resolve(name: str) -> object:
    parts = name.split(".")
    obj: object = importlib.import_module(parts[0])
    for i, part in enumerate(parts[1:], 1):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            obj = importlib.import_module(".".join(parts[: i + 1]))
    return obj


def test_api_pages_name_existing_objects() -> None:
    pytest.importorskip("gymnasium")
    pytest.importorskip("pettingzoo")
    for target in _api_targets():
        _resolve(target)  # raises if the page names something the package no longer has


def test_api_pages_cover_the_public_api() -> None:
    targets = _api_targets()
    missing = [f"fuzzyq.{n}" for n in fuzzyq.__all__ if f"fuzzyq.{n}" not in targets]
    # `fuzzyq.envs` is documented whole (every name of its __all__), or name by name.
    if "fuzzyq.envs" not in targets:
        envs = pytest.importorskip("fuzzyq.envs")
        assert isinstance(envs, types.ModuleType)
        missing += [f"fuzzyq.envs.{n}" for n in envs.__all__ if f"fuzzyq.envs.{n}" not in targets]
    assert not missing, f"not in docs/site/api/*.md: {missing}"


def test_the_site_navigation_lists_existing_pages() -> None:
    config = (ROOT / "mkdocs.yml").read_text()
    pages = re.findall(r"^\s*-\s+(?:[^:\n]+:\s+)?([\w/.-]+\.md)\s*$", config, re.M)
    assert "index.md" in pages and "design.md" in pages
    for page in pages:
        assert (SITE / page).is_file(), page
    for figure in re.findall(
        r"\]\((?:\.\./)*figures/([\w.-]+)\)",
        "".join(p.read_text() for p in SITE.rglob("*.md") if p.is_file()),
    ):
        assert (ROOT / "docs" / "figures" / figure).is_file(), figure


# The stubs' Literal options: a misspelt option fails type checking.


def test_misspelt_options_fail_mypy(tmp_path: Path) -> None:
    api = pytest.importorskip("mypy.api")
    source = tmp_path / "typos.py"
    source.write_text(
        "import fuzzyq\n"
        "model = fuzzyq.PointMass(agents=1)\n"
        "solution = fuzzyq.solve(model, model.paper_grid())\n"
        'solution.policy("greedy")\n'
        'solution.policy("gredy")\n'
        'fuzzyq.solve(model, model.paper_grid(), sweep="asynchronous")\n'
        'fuzzyq.solve(model, model.paper_grid(), precision="f16")\n'
        'fuzzyq.DcMotor("toolbox_demo")\n'
        'fuzzyq.PointMass(integrator="euler")\n'
    )
    stdout, _, status = api.run(
        [
            "--strict",
            "--cache-dir",
            str(tmp_path / ".mypy_cache"),
            "--no-error-summary",
            str(source),
        ]
    )
    assert status == 1, stdout
    lines = sorted(int(m) for m in re.findall(r"typos\.py:(\d+): error", stdout))
    assert lines == [5, 6, 7, 8, 9], stdout


# The headline figures: one source, docs/headline-figures.md, copied verbatim between markers
# into README.md, BENCHMARKS.md and the site's performance page; the pages a newcomer reads
# first quote no timing of their own, so no second figure for the same thing can disagree.

HEADLINE_SOURCE = ROOT / "docs" / "headline-figures.md"
HEADLINE_COPIES = [ROOT / "README.md", ROOT / "BENCHMARKS.md", SITE / "performance.md"]
HEADLINE_MARKED = re.compile(
    r"<!-- headline-figures:start -->\n(.*?)<!-- headline-figures:end -->", re.S
)
# A duration: a number or a range of numbers, then a unit of time ("1.5 s", "12-20 s", "8 ms").
TIMING = re.compile(r"\b\d+(?:\.\d+)?(?:-\d+(?:\.\d+)?)?\s?(?:s|ms|us|µs|ns|sec|seconds?)\b")


def _headline_table() -> str:
    """The source's table, without the comment that opens the file."""
    return re.sub(r"\A<!--.*?-->\n+", "", HEADLINE_SOURCE.read_text(), flags=re.S)


def test_headline_figures_agree() -> None:
    table = _headline_table()
    rows = [line for line in table.splitlines() if line.startswith("|")]
    assert len(rows) >= 4 and all(row.count("|") == 5 for row in rows), table
    for page in HEADLINE_COPIES:
        copies = HEADLINE_MARKED.findall(page.read_text())
        assert copies, f"{page.relative_to(ROOT)} has no headline-figures markers"
        for copy in copies:
            assert copy == table, (
                f"{page.relative_to(ROOT)}: the headline figures differ from "
                "docs/headline-figures.md; copy the table there verbatim"
            )
    for page in [ROOT / "README.md", SITE / "index.md", SITE / "getting-started.md"]:
        outside = HEADLINE_MARKED.sub("", page.read_text())
        stray = [m.group(0) for m in TIMING.finditer(outside)]
        assert not stray, (
            f"{page.relative_to(ROOT)} quotes timings outside the headline table: {stray}; "
            "point to the table instead"
        )
