"""The command examples of README.md and docs/**/*.md, run and compared with what they show,
and the links between those pages checked.

A fenced block right after a line `<!-- docs-check -->` is checked: each line starting with
`$ ` is a command (`chladni …` runs the binary given), the lines after it up to the next
command or blank line are its output (stdout, then stderr). A line `…` in the shown output
stands for any number of lines. Commands run in a scratch folder holding a link to the
repository's `examples/`, so relative paths in the docs work and files they write go nowhere.

    python3 scripts/lib/docs_check.py BINARY [--update]
    python3 scripts/lib/docs_check.py --links      # the links alone, no binary needed

Every relative link `[text](path#anchor)` outside code blocks must name a file that exists
and, for a Markdown file, a heading whose GitHub anchor is `anchor`.

--update rewrites the output of every example that no longer matches with what it prints now
(elisions there are dropped; put them back by hand if the output is long).
"""

import os
import re
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MARK = "<!-- docs-check -->"


def blocks(text):
    """(start, end) line indices of the body of each marked fenced block."""
    lines = text.split("\n")
    found = []
    for i, line in enumerate(lines):
        if line.strip() == MARK and i + 1 < len(lines) and lines[i + 1].startswith("```"):
            end = next(j for j in range(i + 2, len(lines)) if lines[j].startswith("```"))
            found.append((i + 2, end))
    return lines, found


def examples(body):
    """[(command, shown output lines, (first, last) output line index in body)]."""
    out, i = [], 0
    while i < len(body):
        if not body[i].startswith("$ "):
            i += 1
            continue
        command, j = body[i][2:], i + 1
        while j < len(body) and body[j] != "" and not body[j].startswith("$ "):
            j += 1
        out.append((command, body[i + 1 : j], (i + 1, j)))
        i = j
    return out


def matches(shown, got):
    """Whether `got` lines are `shown`, where a `…` line stands for any lines."""
    pattern = "".join(
        r"(?:.*\n)*?" if line.strip() == "…" else re.escape(line) + r"\n" for line in shown
    )
    return re.fullmatch(pattern, "".join(l + "\n" for l in got)) is not None


def run(command, binary, cwd):
    words = shlex.split(command.split("  #")[0])
    if words[0] == "chladni":
        words[0] = binary
    done = subprocess.run(words, cwd=cwd, capture_output=True, text=True, timeout=120)
    text = done.stdout + done.stderr
    return text.rstrip("\n").split("\n") if text.strip() else []


def pages():
    """README.md and every Markdown page under docs/ (docs/evidence/ included), in the order
    their examples run."""
    return [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))


def prose(text):
    """(line number, line) of the lines outside fenced code blocks."""
    fenced = False
    for number, line in enumerate(text.split("\n"), 1):
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced:
            yield number, line


def anchor(heading):
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(path):
    found, seen = set(), {}
    for _, line in prose(path.read_text()):
        heading = re.match(r"#{1,6} (.*)", line)
        if heading:
            name = anchor(heading.group(1))
            found.add(name if name not in seen else f"{name}-{seen[name]}")
            seen[name] = seen.get(name, 0) + 1
    return found


def broken_links():
    """'file:line: what' for every relative link that names no file or no heading."""
    broken = []
    for path in pages():
        for number, line in prose(path.read_text()):
            for target in re.findall(r"\]\(([^)\s]+)\)", line):
                if re.match(r"[a-z]+:", target):
                    continue  # http:, mailto:
                name, _, fragment = target.partition("#")
                dest = (path.parent / name).resolve() if name else path
                where = f"{path.relative_to(ROOT)}:{number}"
                if not dest.exists():
                    broken.append(f"{where}: {target}: no such file")
                elif fragment and dest.suffix == ".md" and fragment not in anchors(dest):
                    broken.append(f"{where}: {target}: no heading with that anchor")
    return broken


def main():
    broken = broken_links()
    print("\n".join(broken + [f"links: {len(broken)} broken"]))
    if sys.argv[1:] == ["--links"]:
        return 1 if broken else 0
    binary = str(Path(sys.argv[1]).resolve())
    update = "--update" in sys.argv[2:]
    files = pages()
    failures, count, start = len(broken), 0, time.monotonic()
    with tempfile.TemporaryDirectory(prefix="chladni-docs-check-") as scratch:
        os.symlink(ROOT / "examples", Path(scratch) / "examples")
        for path in files:
            lines, found = blocks(path.read_text())
            edits = []  # (line range in the file, new lines), applied last to first
            for first, end in found:  # in order: a later command may read an earlier one's file
                for command, shown, (a, b) in examples(lines[first:end]):
                    count += 1
                    got = run(command, binary, scratch)
                    if matches(shown, got):
                        continue
                    where = f"{path.relative_to(ROOT)}:{first + a}"
                    if update:
                        edits.append(((first + a, first + b), got))
                        print(f"updated {where}: $ {command}")
                    else:
                        failures += 1
                        print(f"{where}: $ {command}\n  shown:\n    " + "\n    ".join(shown)
                              + "\n  printed now:\n    " + "\n    ".join(got))
            for (a, b), got in reversed(edits):
                lines[a:b] = got
            if edits:
                path.write_text("\n".join(lines))
    took = time.monotonic() - start
    print(f"docs check: {count} command example(s), {failures} differ ({took:.1f} s)")
    if failures:
        print("if the new output is right: scripts/docs-check.sh --update, then review the diff")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
