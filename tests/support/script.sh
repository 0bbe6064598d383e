# Sourced by the shell tests that run the stages (tests/faults, tests/world):
#   . "$(dirname "$0")/../support/script.sh" NAME REPO BIN_DIR
# sets repo and bin (absolute), work (a fresh folder, removed at exit after
# on_exit, which a test may redefine), fail MESSAGE (says "NAME: FAILED:"
# and exits 1) and canonical PATH (an output as text, to compare runs).
set -uo pipefail
test_name=$1
repo=$(cd "$2" && pwd)
bin=$(cd "$3" && pwd)
work=$(mktemp -d "${TMPDIR:-/tmp}/tigerlod-${test_name// /-}-XXXXXX") # no space: the tests split commands on it
on_exit() { :; }
trap 'on_exit; rm -rf "$work"' EXIT
fail() {
  echo "$test_name: FAILED: $*"
  exit 1
}
# An output as text, one line a file (its digest, by name): the same inputs
# and options give the same bytes. The files that hold measured times only
# parse: the stages' reports, ingest's timings (JSON) and render's frame
# times and summary.
canonical() {
  local p=$1
  if [ -d "$p" ]; then
    (cd "$p" && find . -type f | LC_ALL=C sort | while read -r f; do
      case "$f" in
      *-report.json | *-timings.json | ./summary.json)
        echo "$f"
        python3 -c "import json,sys; json.load(open(sys.argv[1]))" "$f" || echo "not JSON"
        ;;
      ./frames-*.csv) echo "$f" ;;
      *) sha256sum "$f" ;;
      esac
    done)
  else
    sha256sum <"$p"
  fi
}
