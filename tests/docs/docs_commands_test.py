"""The docs check: every `hanzo-fusion` command written in README.md and docs/*.md names a
subcommand and options the program has, and every configuration key the docs write
(`fusion.frontend.X`, `frontend.X`) is one the configuration loader takes. Commands are taken from ```bash blocks (lines
joined at a trailing backslash); a subcommand path is followed through the `--help` pages, and
each `--option` must appear in the final page (or the program's global options).

Run by ctest (docs.commands): python3 docs_commands_test.py --cli build/apps/hanzo-fusion --root .
Exits 1 listing every mismatch as FILE:LINE: what."""

import argparse
import functools
import pathlib
import re
import shlex
import subprocess
import sys


@functools.lru_cache(maxsize=None)
def _help_page(cli, joined):
    result = subprocess.run([cli, *joined.split(), "--help"], capture_output=True, text=True, timeout=30)
    return result.stdout if result.returncode == 0 else None


def help_text(cli, path):
    """The `--help` page of the subcommand path (None when it fails), run once per path."""
    return _help_page(cli, " ".join(path))


def subcommands(text):
    names, inside = set(), False
    for line in text.splitlines():
        if line.startswith("Subcommands:"):
            inside = True
        elif inside and line.startswith("  ") and line.strip():
            names.add(line.split()[0])
        elif inside and line.strip() and not line.startswith(" "):
            inside = False
    return names


def commands(markdown):
    """(line number, command text) of each hanzo-fusion command in the file's bash blocks."""
    in_bash, pending, start = False, "", 0
    for number, line in enumerate(markdown.splitlines(), 1):
        stripped = line.strip()
        if stripped.startswith("```"):
            in_bash = not in_bash and stripped in ("```bash", "```sh", "```shell")
            pending = ""
            continue
        if not in_bash:
            continue
        if not pending:
            start = number
        pending += stripped[:-1] + " " if stripped.endswith("\\") else stripped
        if stripped.endswith("\\"):
            continue
        text, pending = pending, ""
        at = text.find("build/apps/hanzo-fusion ")
        if at >= 0:
            yield start, text[at + len("build/apps/hanzo-fusion "):]


def check_command(cli, text):
    """Mismatches of one command (empty when it is one the program takes)."""
    text = re.sub(r"\s#.*$", "", text)  # a trailing comment
    try:
        tokens = shlex.split(text)
    except ValueError:
        return []
    words = []
    for token in tokens:
        if token in ("|", ">", ">>", "&&", ";", "2>", "&", "<") or token.startswith(("2>", ">")):
            break
        words.append(token.strip("[]"))
    path, problems = [], []
    page = help_text(cli, path)
    global_page = page
    for word in words:
        if word.startswith("-"):
            continue
        if word in subcommands(page):
            path.append(word)
            page = help_text(cli, path)
            if page is None:
                return [f"`hanzo-fusion {' '.join(path)} --help` fails"]
        elif not path:
            return [f"unknown subcommand '{word}'"]
        else:
            break  # positional arguments follow
    for word in words:
        if not word.startswith("--") or word == "--":
            continue
        option = word.split("=")[0]
        if not re.search(re.escape(option) + r"\b", page) and not re.search(re.escape(option) + r"\b", global_page):
            problems.append(f"`hanzo-fusion {' '.join(path)}` has no option {option}")
    return problems


def configuration_keys(root, documents):
    """Configuration keys written in the docs (`fusion.frontend.X`, `frontend.X`) that the
    configuration loader does not take."""
    loader = (root / "src" / "config" / "fusion_config_yaml.cpp").read_text()
    known = set(re.findall(r'"([a-z_]+)"', loader))
    problems = []
    for document in documents:
        for number, line in enumerate(document.read_text().splitlines(), 1):
            for key in re.findall(r"`(?:fusion\.)?(frontend\.[a-z_.<>]+)`", line):
                for part in key.split("."):
                    if part.startswith("<") or part in known:
                        continue
                    problems.append(f"{document.relative_to(root)}:{number}: `{key}`: the configuration loader has no key '{part}'")
    return problems


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--cli", required=True)
    parser.add_argument("--root", required=True)
    arguments = parser.parse_args()
    root = pathlib.Path(arguments.root)
    problems, checked = [], 0
    documents = [root / "README.md", *sorted((root / "docs").glob("*.md"))]
    for document in documents:
        for number, command in commands(document.read_text()):
            checked += 1
            problems += [f"{document.relative_to(root)}:{number}: {problem}" for problem in check_command(arguments.cli, command)]
    problems += configuration_keys(root, documents)
    for problem in problems:
        print(problem)
    print(f"docs check: {checked} commands, {len(problems)} mismatches")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
