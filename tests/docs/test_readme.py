"""The README is read in two minutes: at most 150 lines, the two commands, no dated measurement or
machine load, and one working link per reader, the artist's quickstart among them."""
from __future__ import annotations

import re

from conftest import ROOT

README = ROOT / "README.md"
DATED_OR_LOAD = re.compile(r"20[0-9]{2}-[01][0-9]-[0-3][0-9]|load (average )?[0-9]")


def readme() -> str:
    return README.read_text(encoding="utf-8")


def test_the_readme_is_short_and_names_the_two_commands():
    text = readme()
    assert len(text.splitlines()) <= 150
    assert "make demo" in text and "make test" in text


def test_the_readme_holds_no_dated_measurement_or_machine_load():
    found = DATED_OR_LOAD.findall(readme())
    assert not found, f"the README quotes dates or loads: {found}"
    assert DATED_OR_LOAD.search("at load 1.8") and DATED_OR_LOAD.search("on 2026-12-06")   # the check sees them


def test_every_relative_link_and_picture_of_the_readme_exists():
    links = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", readme())
    local = [link for link in links if not re.match(r"[a-z]+:", link)]
    assert local, "the README links nowhere"
    missing = [link for link in local if not (ROOT / link).exists()]
    assert not missing, f"the README links to missing files: {missing}"


def test_each_reader_is_one_click_from_the_readme_and_the_picture_is_the_projects():
    text = readme()
    for page in ("docs/artists/quickstart.md", "docs/technical/", "docs/architecture.md"):
        assert f"]({page}" in text, page
    pictures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert pictures and all(p.startswith("docs/_static/") for p in pictures)
    made = (ROOT / "docs" / "_static" / "make_pictures.py").read_text(encoding="utf-8")
    assert all(p.rpartition("/")[2] in made for p in pictures), "a README picture no script makes"
