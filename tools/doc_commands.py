#!/usr/bin/env python3
"""Runs the commands a Markdown page shows, so the page cannot drift from the software.

In every ```sh block, each line that starts with `oils ` or `cargo run` is run (its
trailing `# comment` dropped; `oils` is the release binary), in a scratch directory, one
after the other, and must exit 0. A ```text block right after the comment
`<!-- output of: COMMAND -->` is COMMAND's shown output: COMMAND is run and every shown
line but `...` must be one of the lines it printed, run ids (16 hex digits) aside; a
`...` inside a line stands for a figure that varies from run to run (a size that holds
wall-clock timings).

With `--flags`, the pages' commands are not run (campaigns, training, two processes
by hand, placeholders such as `<id>`): each command shown in any code block, usage
synopses included, names its subcommand, and every `--flag` it shows must be one that
subcommand's `--help` lists.

    tools/doc_commands.py README.md [docs/X.md ...]   (needs target/release/oils built)
    tools/doc_commands.py --flags docs/*.md
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
                want = re.escape(RUN_ID.sub("<id>", line.rstrip())).replace(re.escape("..."), ".+")
                if not any(re.fullmatch(want, p) for p in printed):
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


HELP = {}


def help_of(words):
    """The `--help` text of the longest subcommand path at the start of `words`."""
    path = []
    for w in words:
        if w.startswith("-") or not re.fullmatch(r"[a-z][a-z0-9-]*", w):
            break
        path.append(w)
    while path:
        key = tuple(path)
        if key not in HELP:
            out = subprocess.run([OILS, *path, "--help"], capture_output=True, text=True)
            HELP[key] = out.stdout if out.returncode == 0 else None
        if HELP[key] is not None:
            return key, HELP[key]
        path.pop()
    return (), None


def shown_commands(text):
    """Each `oils ...` or `cargo run ... -- ...` command in a code block (continued
    lines joined), as the words after `oils`."""
    for _, body, _ in blocks(text):
        joined, line = [], ""
        for raw in body:
            line += raw.rstrip().rstrip("\\")
            if raw.rstrip().endswith("\\"):
                line += " "
                continue
            joined.append(line.strip())
            line = ""
        for command in joined:
            for part in re.split(r"\s(?:&&|\|)\s", command):
                words = part.lstrip("$ ").split("#")[0].split()
                if words[:1] == ["oils"]:
                    yield part, words[1:]
                elif words[:2] == ["cargo", "run"] and "--" in words and not {"--example", "-p", "--bin"} & set(words[: words.index("--")]):
                    rest = words[words.index("--") + 1 :]
                    if not rest[:1] or rest[0].startswith("-"):
                        continue
                    yield part, rest


def check_flags(page):
    checked = 0
    for command, words in shown_commands(open(page).read()):
        sub, text = help_of(words)
        if text is None:
            raise SystemExit(f"{page}: `{command}`: no such oils subcommand")
        for flag in re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", " ".join(words)):
            if not re.search(rf"(?<![\w-]){re.escape(flag)}(?![\w-])", text):
                raise SystemExit(f"{page}: `{command}`: `oils {' '.join(sub)}` has no {flag}")
        checked += 1
    print(f"{page}: {checked} commands name only flags their subcommand has")
    return checked


def main():
    if sys.argv[1:2] == ["--flags"]:
        pages = sys.argv[2:]
        total = sum(check_flags(p) for p in pages)
        if total == 0:
            raise SystemExit("no command found: the pages show none, or the script lost them")
        return
    pages = sys.argv[1:] or ["README.md"]
    with tempfile.TemporaryDirectory(prefix="oils-doc-") as cwd:
        total = sum(check(os.path.join(REPO, p) if not os.path.isabs(p) else p, cwd) for p in pages)
    if total == 0:
        raise SystemExit("no command found: the pages show none, or the script lost them")
    print(f"{total} commands as the pages show them")


if __name__ == "__main__":
    main()
