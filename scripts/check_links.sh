#!/usr/bin/env bash
# Checks that every link in README.md and docs/ (recursively) resolves: markdown links and
# images `[text](target)` to a file or folder relative to the page, their `#anchor` to a heading
# of the target page (GitHub's slugs), and repository paths named in the text (`docs/x.md`,
# `scripts/x.sh`, `src/x.rs`, ...; not in docs/lab/, which is history) to files that exist.
# Web links are not fetched. Plain python3, no dependency; well under a second.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
python3 - "$@" <<'PY'
import pathlib, re, sys

root = pathlib.Path(".").resolve()
pages = [pathlib.Path("README.md")] + sorted(pathlib.Path("docs").rglob("*.md"))

def slugs(page):
    """GitHub's heading anchors: lower case, punctuation dropped, spaces to hyphens, -N for repeats."""
    seen, out, fence = {}, set(), False
    for line in page.read_text().splitlines():
        if line.startswith("```"):
            fence = not fence
        m = None if fence else re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        s = re.sub(r"[^\w\- ]", "", m.group(1).lower()).replace(" ", "-")
        n = seen.get(s, 0)
        seen[s] = n + 1
        out.add(s if n == 0 else f"{s}-{n}")
    return out

LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
# Repository paths in prose or code spans; outputs a command writes are not checked (they follow
# --out / > and need not exist), nor globs, nor paths outside the repository.
PATH = re.compile(r"(?<![\w./-])((?:docs|scripts|src|tools|samples|tests|exporters|python_bridge|examples|fuzz)"
                  r"/[\w./-]*\.(?:md|sh|py|rs|toml|mjs|png))\b")
bad, links, paths = [], 0, 0
cache = {}
for page in pages:
    fence = False
    for n, line in enumerate(page.read_text().splitlines(), 1):
        if line.startswith("```"):
            fence = not fence
        for target in LINK.findall(line) if not fence else []:
            if re.match(r"[a-z]+:", target):
                continue  # http(s), mailto: not fetched
            links += 1
            file, _, anchor = target.partition("#")
            dest = (page.parent / file).resolve() if file else page.resolve()
            if not dest.exists():
                bad.append(f"{page}:{n}: {target}: no such file")
                continue
            if anchor:
                if dest.is_dir() or dest.suffix != ".md":
                    bad.append(f"{page}:{n}: {target}: an anchor on a non-page")
                elif anchor not in cache.setdefault(dest, slugs(dest)):
                    bad.append(f"{page}:{n}: {target}: no heading '#{anchor}' in {dest.relative_to(root)}")
        # Lab entries are history: the paths their prose names were right on their date.
        for m in PATH.finditer(line) if page.parts[:2] != ("docs", "lab") else []:
            p = m.group(1).rstrip(".")
            before = line[: m.start()]
            if re.search(r"(--out|--[a-z-]*out|--png|--plot-[a-z]+|--log|--view|>)\s*[\"']?$", before):
                continue  # an output the command writes
            if re.search(r"(^|/)[A-Z][A-Z_]*(\.|/)", p):
                continue  # a placeholder (src/cli/NAME.rs)
            paths += 1
            if not (root / p).exists():
                bad.append(f"{page}:{n}: {p}: no such file in the repository")
if bad:
    print(f"{len(bad)} broken link(s):", *bad, sep="\n  ", file=sys.stderr)
    sys.exit(1)
print(f"ok: {links} links and {paths} repository paths in {len(pages)} pages resolve")
PY
