#!/usr/bin/env bash
# Writes docs/reference/commands.md from the binary's own help: `garmentbake --help`, then
# `garmentbake COMMAND --help` for every command (and every subcommand of batch, bench, map), so
# the reference says what the program says. Run after changing a flag or its help text:
#   bash scripts/reference_commands.sh [BINARY]   (default target/debug/garmentbake)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
gb="${1:-target/debug/garmentbake}"
out=docs/reference/commands.md
# The commands a help text lists: the lines under "Commands:" up to the next blank line.
commands() { "$gb" "$@" --help | awk '/^Commands:/{on=1; next} on && /^$/{exit} on && /^  [a-z]/ && $1 != "help" {print $1}'; }
section() {  # a heading and the help text of `garmentbake $*`
  echo "## \`garmentbake${*:+ $*}\`"
  echo
  echo '```text'
  COLUMNS=100 "$gb" "$@" --help | sed 's/[[:space:]]*$//'
  echo '```'
  echo
}
{
  echo "# Commands"
  echo
  echo "What \`garmentbake COMMAND --help\` prints, for every command (written by"
  echo "\`bash scripts/reference_commands.sh\` from the binary; do not edit by hand). How to use them"
  echo "together: [the guides](../guide/README.md); the files they read and write: [formats.md](formats.md)."
  echo
  for c in $(commands); do
    subs=$(commands "$c")
    if [ -n "$subs" ]; then
      for s in $subs; do echo "- [\`$c $s\`](#garmentbake-$c-$s)"; done
    else
      echo "- [\`$c\`](#garmentbake-$c)"
    fi
  done
  echo
  section
  for c in $(commands); do
    section "$c"
    for s in $(commands "$c"); do section "$c" "$s"; done
  done
} > "$out.tmp"
mv "$out.tmp" "$out"
echo "wrote $out ($(wc -l < "$out") lines)"
