"""The documentation site: ``mkdocs build --strict`` passes (no broken link, anchor or API reference), offline.

The build reads the package's docstrings statically (mkdocstrings' griffe), so it imports nothing heavy; it takes
about 10-25 s on a 2-core machine. The README is the site's entry point on GitHub and keeps the quick start's two
commands byte for byte (CI and users run them as written).
"""

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
QUICK_START = (
    "bash scripts/bootstrap.sh && .venv/bin/embodied-adhoc run toxic-waste --agent hotspot --seed 0 --record runs/demo",
    "bash scripts/test.sh",
)
HISTORY = re.compile(r"issue [0-9]+|load average", re.IGNORECASE)


class _AnyTag(yaml.SafeLoader):
    """mkdocs.yml may hold ``!!python/name:`` tags (pymdownx options); read them as plain strings."""


_AnyTag.add_multi_constructor("", lambda loader, suffix, node: suffix)


def _config() -> dict:
    return yaml.load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"), Loader=_AnyTag)


def _load_hooks():
    spec = importlib.util.spec_from_file_location("mkdocs_hooks", ROOT / "scripts" / "mkdocs_hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_site_builds_strict_with_its_api_reference(tmp_path):
    site = tmp_path / "site"
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    log = done.stdout + done.stderr
    assert done.returncode == 0, log
    assert "WARNING" not in log, log
    # the API pages hold the rendered docstrings, not unresolved ":::" directives
    agents = (site / "api" / "agents" / "index.html").read_text(encoding="utf-8")
    assert "task_posterior" in agents and ":::" not in agents
    solvers = (site / "api" / "solvers" / "index.html").read_text(encoding="utf-8")
    assert "PerseusConfig" in solvers and "read_pomdp" in solvers
    envs = (site / "api" / "envs" / "index.html").read_text(encoding="utf-8")
    assert "ToxicWasteEnv" in envs and "LabConfig" in envs
    # nothing on a built page is fetched from elsewhere: no web fonts, no remote scripts or styles
    for page in site.rglob("*.html"):
        html = page.read_text(encoding="utf-8")
        assert "fonts.googleapis" not in html and "fonts.gstatic" not in html, page
        assert not re.search(r'<(?:script|link)[^>]+(?:src|href)="https?://', html), page


def test_the_configuration_builds_offline():
    config = _config()
    assert config["strict"] is True
    assert config["theme"]["name"] == "material"
    assert config["theme"]["font"] is False
    names = [next(iter(p)) if isinstance(p, dict) else p for p in config["plugins"]]
    assert "mkdocstrings" in names
    assert not {"privacy", "social", "material/privacy", "material/social"} & set(names)


def test_every_page_under_docs_results_joins_the_results_section(tmp_path):
    hooks = _load_hooks()
    (tmp_path / "results").mkdir()
    for name in ("tiger.md", "index.md", "atpo.md"):
        (tmp_path / "results" / name).write_text("# x\n")
    nav = [{"Home": "index.md"}, {"Results": ["reproducing.md", {"Tiger": "results/tiger.md"}]}]
    config = hooks.on_config({"nav": nav, "docs_dir": str(tmp_path)})
    assert config["nav"][1]["Results"] == [
        "reproducing.md",
        {"Tiger": "results/tiger.md"},
        "results/index.md",
        "results/atpo.md",
    ]
    assert hooks.result_pages(tmp_path / "absent", set()) == []


def test_the_readme_is_short_and_keeps_the_two_commands():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) <= 150
    for command in QUICK_START:
        assert command in readme.splitlines(), command
    assert "<!-- results:headline start -->" in readme and "<!-- results:headline end -->" in readme


def test_user_pages_and_code_carry_no_development_history():
    pages = [ROOT / "README.md", *(ROOT / "docs").rglob("*.md"), *(ROOT / "embodied_adhoc").rglob("*.py")]
    found = [
        f"{path.relative_to(ROOT)}:{number}: {line.strip()[:80]}"
        for path in pages
        if path != ROOT / "docs" / "changelog.md"
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1)
        if HISTORY.search(line)
    ]
    assert not found, "history belongs in docs/changelog.md:\n" + "\n".join(found)


def test_docstring_roles_read_as_plain_code():
    hooks = _load_hooks()
    html = 'see :class:<code>~pkg.Agent</code>, :py:func:<code>run</code>; it::</p>\n<div class="highlight"><pre>'
    assert (
        hooks.readable_roles(html)
        == 'see <code>pkg.Agent</code>, <code>run</code>; it:</p>\n<div class="highlight"><pre>'
    )
    # a double colon that does not introduce a code block, and code without a role, stay as written
    assert hooks.readable_roles("a::</p><p>b <code>~x</code>") == "a::</p><p>b <code>~x</code>"
