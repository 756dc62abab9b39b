"""Chapter headers: the paper's reference from references.bib and a re-run box whose command
lines the CLI accepts and whose table lists every parameter."""

import re
import shlex

import pytest

from railpaper.cli import build_parser
from railpaper.pipeline.chapters import book_chapters, chapter_spec, paper_chapters
from railpaper.pipeline.header import (
    CHAPTER_REFERENCES,
    bib_entries,
    parameter_unit,
    reference_markdown,
    rerun_markdown,
)


@pytest.mark.parametrize("chapter", paper_chapters())
def test_every_chapter_has_a_reference_with_title_and_year(chapter):
    entry = bib_entries()[CHAPTER_REFERENCES[chapter]]
    text = reference_markdown(chapter)
    assert entry["title"] in text and f"({entry['year']})" in text
    assert f"{{cite:p}}`{CHAPTER_REFERENCES[chapter]}`" in text


def test_doi_links_and_volume_pages():
    assert "https://doi.org/10.21595/jve.2016.17354" in reference_markdown("partial-state-observer")
    assert "14(3): 52–57" in reference_markdown("rbpf-parameter-estimation")


@pytest.mark.parametrize("chapter", book_chapters())
def test_rerun_box_lists_parameters_and_valid_commands(chapter):
    text = rerun_markdown(chapter)
    spec = chapter_spec(chapter)
    for p in spec.parameters:
        assert f"| `{p.name}` |" in text
    block = re.search(r"```text\n(.*?)```", text, re.S).group(1)
    commands = [shlex.split(line)[1:] for line in block.strip().splitlines()]
    assert len(commands) == 5
    for argv in commands:
        args = build_parser().parse_args(argv)          # SystemExit on an invalid line
        if args.command == "run":
            overrides = {name: value for name, value in args.parameter or []}
            for name in overrides:
                spec.parameter(name)
    assert text.startswith("````{dropdown}") and text.rstrip().endswith("````")


@pytest.mark.parametrize("name, unit", [("speeds_kmh", "km/h"), ("alpha_per_s", "1/s"),
                                        ("dt_s", "s"), ("noise_acc_body_mps2", "m/s²"),
                                        ("initial_error_m", "m"), ("n_particles", "")])
def test_units_from_names(name, unit):
    assert parameter_unit(name) == unit
