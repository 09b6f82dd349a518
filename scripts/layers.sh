#!/usr/bin/env bash
# Checks that data flows one way through src/: lists the crate:: imports of every top-level
# module and fails if one imports a module on its own layer or above, or if two files of one
# module import each other. Unit-test modules (a file's trailing `#[cfg(test)] mod`) are not
# counted. The layers are read from the table in docs/architecture.md (between its
# `<!-- layers:` markers), and the table is checked against the code: every top-level module of
# src/ listed once, nothing listed that src/ lacks, layers numbered 1.. with no gap, src/lib.rs's
# `pub mod`s and its header's numbered list equal to the table.
# And the house rules of src/cli/ (docs/architecture.md, "Where to add… A command"): a command
# file imports no other command's module (only the shared cli/args.rs, its files under cli/args/,
# and cli/mod.rs), no module below cli imports `cli::`, and every file of src/cli/ (its
# subfolders too) stays within CLI_LINES lines.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
python3 - "$@" <<'PY'
import pathlib, re, sys

bad = []
# The layer table of docs/architecture.md: rows `| N | `a` `b` | ... |` between the markers.
doc = pathlib.Path("docs/architecture.md")
rows, inside = {}, False
for n, line in enumerate(doc.read_text().splitlines(), 1):
    if line.startswith("<!-- layers: end"):
        inside = False
    elif line.startswith("<!-- layers:"):
        inside = True
    elif inside and re.match(r"\|\s*\d+\s*\|", line):
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        number, mods = int(cells[0]), re.findall(r"`([a-z_][a-z0-9_]*)`", cells[1])
        if number in rows:
            bad.append(f"{doc}:{n}: layer {number} listed twice")
        if not mods:
            bad.append(f"{doc}:{n}: layer {number} names no module")
        rows[number] = (mods, n)
if not rows:
    sys.exit(f"{doc}: no layer table between its '<!-- layers:' markers")
if sorted(rows) != list(range(1, len(rows) + 1)):
    bad.append(f"{doc}: layers numbered {sorted(rows)}, not 1..{len(rows)}")
# Lowest first; modules on one line are peers and must not import each other.
LAYERS = [" ".join(rows[k][0]) for k in sorted(rows)]
listed = {}
for k in sorted(rows):
    for m in rows[k][0]:
        if m in listed:
            bad.append(f"{doc}:{rows[k][1]}: module '{m}' listed on layers {listed[m]} and {k}")
        listed.setdefault(m, k)
src = pathlib.Path("src")
on_disk = {p.name.removesuffix(".rs"): p for p in src.iterdir()
           if (p.is_dir() or p.suffix == ".rs") and p.name not in ("lib.rs", "main.rs")}
for m in sorted(set(listed) - set(on_disk)):
    bad.append(f"{doc}: lists module '{m}', which src/ does not have (no src/{m}.rs or src/{m}/)")
for m in sorted(set(on_disk) - set(listed)):
    bad.append(f"{on_disk[m]}: module '{m}' has no layer in {doc}'s table")
lib = (src / "lib.rs").read_text()
declared = set(re.findall(r"^pub mod ([a-z_][a-z0-9_]*);", lib, re.M))
for m in sorted(declared ^ set(listed)):
    where = "src/lib.rs declares" if m in declared else f"{doc} lists"
    bad.append(f"{where} module '{m}', the other does not")
# src/lib.rs's header repeats the table as `//! N. `a`, `b` — ...`: it must say the same.
header = {}
for line in lib.splitlines():
    m = re.match(r"//! (\d+)\. (.*)", line)
    if m:
        header[int(m.group(1))] = re.findall(r"`([a-z_][a-z0-9_]*)`", m.group(2).split(" — ")[0])
for k in sorted(set(header) | set(rows)):
    if header.get(k) != (rows[k][0] if k in rows else None):
        bad.append(f"src/lib.rs header, layer {k}: {header.get(k)} where {doc} has "
                   f"{rows[k][0] if k in rows else None}")
layer = {m: i for i, line in enumerate(LAYERS) for m in line.split()}
src = pathlib.Path("src")
uses = {}      # top-level module -> {imported top-level module: first place}
file_uses = {} # file path (module path) -> set of sibling module paths it imports
for f in sorted(src.rglob("*.rs")):
    rel = f.relative_to(src)
    if rel.name in ("lib.rs", "main.rs") and len(rel.parts) == 1:
        continue
    top = rel.parts[0].removesuffix(".rs")
    if top not in layer:
        continue  # reported above: the table lacks it
    parts = [p.removesuffix(".rs") for p in rel.parts]
    if parts[-1] == "mod":
        parts = parts[:-1]
    me = "::".join(parts)
    lines = f.read_text().splitlines()
    for n, line in enumerate(lines, 1):
        # A file's unit tests (the trailing `#[cfg(test)] mod`) may use any layer's fixtures.
        if line.startswith("#[cfg(test)]") and n < len(lines) and lines[n].startswith("mod "):
            break
        code = line.split("//")[0]
        for path in re.findall(r"\bcrate::((?:[a-z_][a-z0-9_]*::?)+)", code):
            segs = [s for s in path.split("::") if s]
            target = segs[0]
            if target == top:
                # Sibling files of one module: record file-level edges for the cycle check.
                if len(segs) >= 2:
                    file_uses.setdefault(me, set()).add("::".join(segs[:2]))
                continue
            uses.setdefault(top, {}).setdefault(target, f"{f}:{n}")
            if target in layer and layer[target] >= layer[top]:
                bad.append(f"{f}:{n}: {top} (layer {layer[top] + 1}) imports {target} (layer {layer[target] + 1})")
# src/cli/: commands are thin, and each stands alone.
CLI_LINES = 250
# Over the limit today, to be thinned (issue 39); each must leave this list when it fits.
CLI_TOO_LONG = {}
cli = src / "cli"
commands = {p.stem for p in cli.glob("*.rs")} - {"mod", "args"}
for f in sorted(cli.rglob("*.rs")):
    lines = f.read_text().splitlines()
    # The shared flags: cli/args.rs and the files of its submodules (cli/args/*.rs).
    shared = f.stem in ("mod", "args") and f.parent == cli or f.parent == cli / "args"
    if not shared:
        for n, line in enumerate(lines, 1):
            code = line.split("//")[0]
            named = re.findall(r"\b(?:super|crate::cli)::([a-z_][a-z0-9_]*)", code)
            for group in re.findall(r"\b(?:super|crate::cli)::\{([^}]*)", code):
                named += re.findall(r"(?:^|,)\s*([a-z_][a-z0-9_]*)", group)
            for other in named:
                if other in commands and other != f.stem:
                    bad.append(f"{f}:{n}: the command {f.stem} imports the command {other}: "
                               "move what they share into the library (or cli/args.rs for flags)")
    if len(lines) > CLI_LINES and f.name not in CLI_TOO_LONG:
        bad.append(f"{f}: {len(lines)} lines, over {CLI_LINES}: move the work into the library")
    if len(lines) <= CLI_LINES and f.name in CLI_TOO_LONG:
        bad.append(f"{f}: {len(lines)} lines now: take it off layers.sh's CLI_TOO_LONG")
for f in sorted(src.rglob("*.rs")):
    if f.parts[1] == "cli" or f.name == "main.rs" and len(f.parts) == 2:
        continue
    for n, line in enumerate(f.read_text().splitlines(), 1):
        if re.search(r"\bcrate::cli\b", line.split("//")[0]):
            bad.append(f"{f}:{n}: library code imports cli (the commands are the top layer)")
for a, targets in file_uses.items():
    for b in targets:
        if b != a and not b.startswith(a + "::") and a in file_uses.get(b, set()):
            if a < b:
                bad.append(f"{a} and {b} import each other")
for i, line in enumerate(LAYERS):
    for m in line.split():
        deps = sorted(uses.get(m, {}), key=lambda d: (layer.get(d, 99), d))
        print(f"{i + 1:>2} {m:<9} imports: {', '.join(deps) or '-'}")
if bad:
    print("\nagainst the layer table (docs/architecture.md):", *bad, sep="\n  ", file=sys.stderr)
    sys.exit(1)
print(f"ok: every import points to a lower layer; no command imports another; cli files within "
      f"{CLI_LINES} lines" + (f" but {len(CLI_TOO_LONG)} listed" if CLI_TOO_LONG else ""))
PY
