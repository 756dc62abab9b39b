"""What every chapter page opens with: the paper's full reference and a "Re-run this chapter" box.

A chapter notebook's first cells call :func:`reference_markdown` and :func:`rerun_markdown` (and
show its claims with :func:`railpaper.pipeline.ledger.chapter_markdown`); the text is built from
``book/references.bib`` and the chapter's :class:`~railpaper.experiments.base.ChapterSpec`, so a
new parameter or a changed default appears on the page without editing it.
"""

from __future__ import annotations

import re
from pathlib import Path

from railpaper.pipeline.chapters import chapter_spec

from railpaper.paths import BOOK_DIR

#: The bibliography key of each chapter's paper in ``book/references.bib``.
CHAPTER_REFERENCES = {
    "reduced-order-observer": "li2014wheelrail",
    "partial-state-observer": "zheng2016wheel",
    "rbpf-parameter-estimation": "ding2014performance",
    "quasi-gaussian-rbpf": "qgrbpf",
}

#: Units read off a parameter name's suffix (the names carry their unit).
UNIT_SUFFIXES = (("_per_s", "1/s"), ("_kmh", "km/h"), ("_mps2", "m/s²"), ("_radps", "rad/s"),
                 ("_mps", "m/s"), ("_s", "s"), ("_m", "m"), ("_hz", "Hz"))


def bib_entries(path: str | Path = BOOK_DIR / "references.bib") -> dict[str, dict[str, str]]:
    """``{key: {field: value}}`` of a BibTeX file (flat fields, braces removed)."""
    text = Path(path).read_text()
    entries = {}
    for match in re.finditer(r"@\w+\{([^,]+),(.*?)\n\}", text, re.S):
        fields = {}
        for name, value in re.findall(r"(\w+)\s*=\s*\{(.*?)\},?\s*$", match.group(2), re.M):
            fields[name.lower()] = value.replace("{", "").replace("}", "").replace("--", "–")
        entries[match.group(1).strip()] = fields
    return entries


def reference_markdown(chapter: str) -> str:
    """The chapter paper's reference in full, with a citation linking to the References page."""
    key = CHAPTER_REFERENCES[chapter]
    e = bib_entries()[key]
    authors = e.get("author", "").replace(" and ", "; ")
    parts = [f"{authors} ({e.get('year', 'n.d.')}). *{e.get('title', '')}*."]
    journal = e.get("journal", "")
    if journal:
        issue = "".join([f", {e['volume']}" if "volume" in e else "",
                         f"({e['number']})" if "number" in e else "",
                         f": {e['pages']}" if "pages" in e else ""])
        parts.append(f"{journal}{issue}.")
    if "doi" in e:
        parts.append(f"DOI [{e['doi']}](https://doi.org/{e['doi']}).")
    if "note" in e:
        parts.append(e["note"] + ".")
    return "**Paper:** " + " ".join(parts) + f" {{cite:p}}`{key}`\n"


def parameter_unit(name: str) -> str:
    """Unit of a parameter from its name's suffix ('' when the name carries none)."""
    for suffix, unit in UNIT_SUFFIXES:
        if name.endswith(suffix):
            return unit
    return ""


def _value(value) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, list):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, str):
        return repr(value) if value else "'' (none)"
    return str(value)


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def rerun_markdown(chapter: str) -> str:
    """A "Re-run this chapter" dropdown: every parameter (default, unit, meaning, quick value)
    and the exact ``railpaper run`` and ``railpaper sweep`` command lines."""
    spec = chapter_spec(chapter)
    example = next((p for p in spec.parameters if p.name != "seed" and p.type in ("float", "int")),
                   spec.parameters[0])
    lines = ["````{dropdown} Re-run this chapter: parameters and commands",
             ":class-container: rerun-box", "",
             f"From a checkout with `make venv` done (see {{doc}}`the reproducibility page "
             "</reproducibility>`):", "", "```text",
             f".venv/bin/railpaper run {chapter} --out runs/my-run",
             f".venv/bin/railpaper run {chapter} -p {example.name} {_value(example.default)} "
             "--out runs/my-run",
             f".venv/bin/railpaper run {chapter} --quick --out runs/quick",
             f".venv/bin/railpaper sweep {chapter} --seeds 0:20 --out runs/my-sweep",
             f".venv/bin/railpaper compare book/chapters/{chapter} runs/my-run", "```", "",
             "`runs/my-run/index.html` is then this page for your run, its claims judged on it. "
             "`-p NAME VALUE` takes YAML values (lists as `'[60, 100]'`).", "",
             "| parameter | default | unit | meaning | quick run |", "|---|---|---|---|---|"]
    for p in spec.parameters:
        quick = "same" if p.quick is None else _value(p.quick)
        unit = parameter_unit(p.name)
        meaning = p.meaning[:-len(unit) - 2] if unit and p.meaning.endswith(f", {unit}") \
            else p.meaning
        lines.append(f"| `{p.name}` | {_cell(_value(p.default))} | {unit} | {_cell(meaning)} | "
                     f"{_cell(quick)} |")
    lines += ["````", ""]
    return "\n".join(lines)
