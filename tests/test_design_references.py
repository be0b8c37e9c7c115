"""Code comments and pages cite docs/DESIGN.md by section title, for example
`(docs/DESIGN.md, "Section title")`, and the title may be split across two
comment lines. Every quoted title must be a heading of docs/DESIGN.md, or the
part of a heading before its first ':', so that a renamed or removed section
fails here instead of leaving the comments pointing nowhere. The design note
outside the repository (named by the pattern below) must not be cited: cite
the paper or a DESIGN section instead."""
import functools
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DESIGN = ROOT / "docs" / "DESIGN.md"
SCANNED = ("python", "cpp", "bench", "tests", "docs", "examples")
EXTENSIONS = {".py", ".h", ".cpp", ".md", ".toml"}
SKIPPED_DIRS = {"__pycache__", ".pytest_cache", "build", "site"}

# A comment line's marker: '#', '//', '///', '/*', '*' or '*/' (Markdown headings
# and bullets lose their marks too, which changes no reference).
COMMENT_MARK = re.compile(r"^\s*(?:#+|/{2,3}|/\*+|\*+/?)?\s*")
# DESIGN or DESIGN.md (or a Markdown link to it), then one or more quoted titles
# separated by ',', 'and' or 'or': DESIGN.md, "A" and "B"; DESIGN.md ("A", "B").
REFERENCE = re.compile(r'DESIGN(?:\.md)?(?:\]\([^)]*\))?[\s,:;(]*'
                       r'((?:"[A-Z][^"]{0,200}"(?:\s*(?:,|and|or)\s*)?)+)')
TITLE = re.compile(r'"([^"]+)"')
# The outside note's name, built so that this file does not cite it itself.
OUTSIDE_NOTE = re.compile(r"\b" + "EMU" + r"\.md\b")


def headings(text: str) -> set:
    """Every heading of a Markdown page, and each one's part before its first ':'."""
    titles = set()
    for match in re.finditer(r"^#{1,6}\s+(.+?)\s*#*\s*$", text, re.M):
        title = match.group(1).strip()
        titles.add(title)
        if ":" in title:
            titles.add(title.split(":", 1)[0].strip())
    return titles


def normalised(text: str) -> str:
    """The file's lines without comment markers, joined by single spaces: a
    title split over two comment lines reads as one."""
    return re.sub(r"\s+", " ", " ".join(COMMENT_MARK.sub("", line) for line in text.splitlines()))


def references(text: str) -> list:
    """The section titles a text cites as DESIGN's."""
    return [title for match in REFERENCE.finditer(normalised(text))
            for title in TITLE.findall(match.group(1))]


def scanned_files():
    here = Path(__file__).resolve()
    files = [ROOT / "README.md"]
    for top in SCANNED:
        for path in sorted((ROOT / top).rglob("*")):
            if (path.suffix in EXTENSIONS and path.is_file() and path.resolve() != here
                    and not SKIPPED_DIRS.intersection(path.relative_to(ROOT).parts)):
                files.append(path)
    return [path for path in files if path.exists()]


@functools.lru_cache(maxsize=None)
def texts() -> dict:
    """{path relative to the repository: text} of every scanned file."""
    return {path.relative_to(ROOT).as_posix(): path.read_text(encoding="utf-8", errors="replace")
            for path in scanned_files()}


def test_references_name_design_sections():
    sections = headings(DESIGN.read_text(encoding="utf-8"))
    wrong = [f'{name}: "{title}"' for name, text in texts().items()
             for title in references(text) if title not in sections]
    assert not wrong, ("references to docs/DESIGN.md sections that are not its headings "
                       "(nor a heading's part before ':'):\n" + "\n".join(wrong))


def test_references_are_found():
    # The scan must see the references it is there to check (a broken pattern
    # would pass the test above on nothing).
    assert sum(len(references(text)) for text in texts().values()) >= 20


def test_no_outside_design_note():
    cited = [f"{name}:{number}" for name, text in texts().items()
             for number, line in enumerate(text.splitlines(), 1) if OUTSIDE_NOTE.search(line)]
    assert not cited, ("files cite a design note that is not in this repository; cite the "
                       "paper or a docs/DESIGN.md section instead:\n" + "\n".join(cited))


def test_the_scan_reads_both_forms():
    text = ('x = 1  # the rule (docs/DESIGN.md,\n'
            '# "Two words") and DESIGN "One" and "Three: more"\n'
            '// see DESIGN.md ("Four", "Five")\n')
    assert references(text) == ["Two words", "One", "Three: more", "Four", "Five"]
    assert headings("# A: b\n\n## C\n") == {"A: b", "A", "C"}
