#!/usr/bin/env python3
"""Runs the commands a Markdown page shows, so the page cannot drift from the software.

In every ```sh block, each line that starts with `oils ` or `cargo run` is run (its
trailing `# comment` dropped; `oils` is the release binary), in a scratch directory, one
after the other, and must exit 0. A ```text block right after the comment
`<!-- output of: COMMAND -->` is COMMAND's shown output: COMMAND is run and every shown
line but `...` must be one of the lines it printed, run ids (16 hex digits) aside.

    tools/doc_commands.py README.md [docs/X.md ...]   (needs target/release/oils built)
"""
import os
import re
import shlex
import subprocess
import sys
import tempfile

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OILS = os.path.join(os.environ.get("CARGO_TARGET_DIR", os.path.join(REPO, "target")), "release", "oils")
RUN_ID = re.compile(r"\b[0-9a-f]{16}\b")


def argv(command):
    """The command line as a list, `oils` and `cargo run` pointed at this checkout."""
    words = shlex.split(command, comments=True)
    if words[0] == "oils":
        return [OILS] + words[1:]
    if words[:2] == ["cargo", "run"]:
        return words[:2] + ["--manifest-path", os.path.join(REPO, "Cargo.toml")] + words[2:]
    raise ValueError(f"not a command this script runs: {command}")


def run(command, cwd):
    out = subprocess.run(argv(command), cwd=cwd, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"FAILED (exit {out.returncode}): {command}\n{out.stdout}\n{out.stderr}")
    return out.stdout


def blocks(text):
    """(language, lines, the comment line before the block) of each fenced block."""
    lines = text.split("\n")
    i = 0
    while i < len(lines):
        m = re.match(r"^```(\w*)\s*$", lines[i])
        if not m:
            i += 1
            continue
        before = lines[i - 1] if i > 0 else ""
        j = i + 1
        while j < len(lines) and not lines[j].startswith("```"):
            j += 1
        yield m.group(1), lines[i + 1 : j], before
        i = j + 1


def check(page, cwd):
    ran = 0
    for lang, body, before in blocks(open(page).read()):
        shown = re.match(r"^<!-- output of: (.*) -->$", before.strip())
        if shown:
            command = shown.group(1)
            printed = {RUN_ID.sub("<id>", l.rstrip()) for l in run(command, cwd).split("\n")}
            for line in body:
                if line.strip() == "...":
                    continue
                if RUN_ID.sub("<id>", line.rstrip()) not in printed:
                    raise SystemExit(f"{page}: `{command}` no longer prints:\n  {line}\nit printed:\n" + "\n".join(sorted(printed)))
            ran += 1
            print(f"{page}: output of `{command}` as shown")
        elif lang == "sh":
            for line in body:
                if re.match(r"^(oils |cargo run)", line):
                    run(line, cwd)
                    ran += 1
                    print(f"{page}: {line.split('#')[0].strip()}")
    return ran


def main():
    pages = sys.argv[1:] or ["README.md"]
    with tempfile.TemporaryDirectory(prefix="oils-doc-") as cwd:
        total = sum(check(os.path.join(REPO, p) if not os.path.isabs(p) else p, cwd) for p in pages)
    if total == 0:
        raise SystemExit("no command found: the pages show none, or the script lost them")
    print(f"{total} commands as the pages show them")


if __name__ == "__main__":
    main()
