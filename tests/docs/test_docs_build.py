"""The docs site builds with warnings as errors, and its references are the code's: every `scenefit`
command and option, every jobs-file key, every internal link resolves; an option added to the parser
shows up in the generated reference; a broken link fails the build."""
from __future__ import annotations

import argparse
import html
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

from conftest import ROOT

DOCS = ROOT / "docs"
SPHINX = ["-W", "-n", "--keep-going", "-q", "-b", "html"]


def sphinx_build(source: Path, out: Path, prelude: str = "") -> subprocess.CompletedProcess:
    """Sphinx in a fresh interpreter (after `prelude`, e.g. a patch of the parser), its doctrees in `out`."""
    code = prelude + textwrap.dedent(f"""
        import sys
        from sphinx.cmd.build import build_main
        sys.exit(build_main({[*SPHINX, "-d", str(out / '.doctrees'), str(source), str(out)]!r}))
    """)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=ROOT)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("docs") / "html"
    built = sphinx_build(DOCS, out)
    assert built.returncode == 0, f"the docs do not build cleanly:\n{built.stdout[-3000:]}\n{built.stderr[-5000:]}"
    return out


def page_text(site: Path, page: str) -> str:
    return html.unescape((site / page).read_text(encoding="utf-8"))


def test_every_command_and_option_is_in_the_cli_reference(site):
    from scenefit.cli import build_parser

    text = page_text(site, "technical/cli.html")
    commands = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices
    assert len(commands) >= 10
    missing = []
    for name, parser in commands.items():
        if not re.search(rf"\b{re.escape(name)}\b", text):
            missing.append(name)
        for action in parser._actions:
            for option in action.option_strings or [action.dest]:
                if option not in text:
                    missing.append(f"{name} {option}")
    assert not missing, f"the CLI reference lacks {missing}"
    flat = " ".join(text.split())
    in_help = {" ".join(help_[max(0, m.start() - 12):m.end()].split()) for parser in commands.values()
               for help_ in (a.help or "" for a in parser._actions) for m in re.finditer(r"--[a-z][a-z-]+", help_)}
    assert in_help and not [words for words in in_help if words not in flat], \
        "an option named in a help text is not shown as typed (smart dashes?)"


def test_every_jobs_file_key_is_in_the_schema(site):
    from scenefit.workers import jobs

    text = page_text(site, "technical/jobs-file.html")
    keys = [*jobs.JOB_KEYS, *jobs.BATCH_KEYS, *jobs.MODEL_KEYS]
    missing = [key for key in keys if not re.search(rf"\b{key}\b", text)]
    assert not missing, f"the jobs-file reference lacks {missing}"


def test_the_presets_table_is_the_preset_tables(site):
    from scenefit.core.pipeline.preset_tables import TABLES

    text = page_text(site, "technical/presets.html")
    assert f">{TABLES['compose']['draft']['noise_target']}<" in text.replace(" ", "")
    assert ">iterations<" in text and str(TABLES["adapt"]["balanced"]["iterations"]) in text


def internal_links(site: Path):
    for page in site.rglob("*.html"):
        for target in re.findall(r'(?:href|src)="([^"]+)"', page.read_text(encoding="utf-8")):
            parts = urlsplit(html.unescape(target))
            if not parts.scheme and not target.startswith(("mailto:", "//")):
                yield page, parts


def test_every_internal_link_resolves(site):
    broken, checked = [], 0
    for page, parts in internal_links(site):
        file = (page.parent / unquote(parts.path)).resolve() if parts.path else page
        checked += 1
        if not file.exists():
            broken.append(f"{page.relative_to(site)} -> {parts.geturl()}")
        elif parts.fragment and file.suffix == ".html" and \
                f'id="{parts.fragment}"' not in file.read_text(encoding="utf-8"):
            broken.append(f"{page.relative_to(site)} -> {parts.geturl()} (no such anchor)")
    assert checked > 100 and not broken, broken


def test_the_quickstart_shows_pictures_the_project_made(site):
    text = (site / "artists" / "quickstart.html").read_text(encoding="utf-8")
    pictures = re.findall(r'<img [^>]*src="([^"]+)"', text)
    assert len(pictures) >= 3
    for picture in pictures:
        assert (site / "artists" / picture).is_file()
    made = set(re.findall(r'"([\w/.]+\.png)"', (DOCS / "_static" / "make_pictures.py").read_text()))
    assert {Path(p).name for p in pictures} <= {Path(m).name for m in made}, "a picture no script makes"


def minimal_site(tmp: Path, page: str) -> Path:
    """conf.py, the extensions and one page beside an index: a site small enough to build twice."""
    source = tmp / "src"
    shutil.copytree(DOCS / "_ext", source / "_ext")
    shutil.copy(DOCS / "conf.py", source / "conf.py")
    (source / "_static").mkdir()
    (source / "index.md").write_text("# Index\n\n```{toctree}\npage\n```\n")
    (source / "page.md").write_text(page)
    return source


def test_an_option_added_to_the_parser_changes_the_reference(tmp_path, site):
    cli_page = (DOCS / "technical" / "cli.md").read_text().replace("{doc}`commands`", "the commands page")
    source = minimal_site(tmp_path, cli_page)
    patch = textwrap.dedent("""
        import argparse
        import scenefit.cli as cli
        plain = cli.build_parser
        def with_dummy():
            parser = plain()
            commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
            commands["run"].add_argument("--dummy-docs-option", help="an option only this test adds")
            return parser
        cli.build_parser = with_dummy
    """)
    built = sphinx_build(source, tmp_path / "dummy", prelude=patch)
    assert built.returncode == 0, built.stderr[-3000:]
    assert "--dummy-docs-option" in page_text(tmp_path / "dummy", "page.html")
    assert "an option only this test adds" in page_text(tmp_path / "dummy", "page.html")
    assert "--dummy-docs-option" not in page_text(site, "technical/cli.html")   # the plain parser's reference


def test_a_broken_internal_link_fails_the_build(tmp_path):
    source = minimal_site(tmp_path, "# Page\n\nSee [the install page](artists/install.md).\n")
    built = sphinx_build(source, tmp_path / "html")
    assert built.returncode != 0
    assert "artists/install" in built.stderr
