"""The README's Python examples run as written; they, the documentation site's Python examples
(docs/site/**/*.md) and examples/*.py type-check with `mypy --strict`."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
DOC_BLOCKS = [
    (f"{page.relative_to(ROOT)} python block {i}", block)
    for page in sorted((ROOT / "docs" / "site").rglob("*.md"))
    if not page.is_symlink()
    for i, block in enumerate(re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S))
]


def test_the_readme_has_python_examples() -> None:
    assert len(BLOCKS) >= 2


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_example_runs(index: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # examples may write files
    exec(compile(BLOCKS[index], f"README.md python block {index}", "exec"), {})


def test_the_readme_installs_from_a_checkout() -> None:
    # fuzzyq is not on PyPI: `pip install fuzzyq[envs]` would fetch another package or none.
    text = README.read_text()
    assert "pip install fuzzyq" not in text
    assert 'pip install ".[envs]"' in text


@pytest.fixture(scope="module")
def mypy_report(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[str]]:
    """`mypy --strict` over every README block (each as its own file) and examples/*.py.

    One run for all files (mypy is slow to start); returns each file's error lines, keyed by
    its name ("README.md python block N" or the example's file name).
    """
    api = pytest.importorskip("mypy.api")
    work = tmp_path_factory.mktemp("mypy")
    names: dict[str, str] = {}
    files = []
    for i, block in enumerate(BLOCKS):
        path = work / f"readme_block_{i}.py"
        path.write_text(block)
        names[str(path)] = f"README.md python block {i}"
        files.append(str(path))
    for i, (name, block) in enumerate(DOC_BLOCKS):
        path = work / f"docs_block_{i}.py"
        path.write_text(block)
        names[str(path)] = name
        files.append(str(path))
    for example in EXAMPLES:
        names[str(example)] = example.name
        files.append(str(example))
    stdout, stderr, status = api.run(
        ["--strict", "--cache-dir", str(work / ".mypy_cache"), "--no-error-summary", *files]
    )
    assert status in (0, 1), f"mypy failed to run:\n{stdout}\n{stderr}"
    report: dict[str, list[str]] = {name: [] for name in names.values()}
    for line in stdout.splitlines():
        path = line.split(":", 1)[0]
        if path in names and ": error:" in line:
            report[names[path]].append(line.replace(path, names[path]))
    unattributed = [
        l for l in stdout.splitlines() if ": error:" in l and l.split(":", 1)[0] not in names
    ]
    assert not unattributed, "mypy errors outside the checked files:\n" + "\n".join(unattributed)
    return report


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_example_passes_mypy_strict(index: int, mypy_report: dict[str, list[str]]) -> None:
    errors = mypy_report[f"README.md python block {index}"]
    assert not errors, "\n".join(errors)


def test_the_site_has_python_examples() -> None:
    assert len(DOC_BLOCKS) >= 5


@pytest.mark.parametrize("name", [name for name, _ in DOC_BLOCKS])
def test_docs_example_passes_mypy_strict(name: str, mypy_report: dict[str, list[str]]) -> None:
    errors = mypy_report[name]
    assert not errors, "\n".join(errors)


@pytest.mark.parametrize("example", [p.name for p in EXAMPLES])
def test_example_passes_mypy_strict(example: str, mypy_report: dict[str, list[str]]) -> None:
    errors = mypy_report[example]
    assert not errors, "\n".join(errors)
