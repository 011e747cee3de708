# Shared by the localization benchmarks (loc_areas.sh, loc_sparse.sh, loc_learned.sh); source it.

# prepare_or_skip INSGEN WORKDIR AREA: prepares AREA. Returns 1 (skip it) when its real data is absent
# outside CI, after saying so; any other failure (or absent data under CI=true) prints the error and
# exits the script.
prepare_or_skip() {
  local ig=$1 w=$2 a=$3
  if ! $ig prepare --area "$a" 2>"$w/prepare.err"; then
    if grep -q -i "not found\|no such file\|missing" "$w/prepare.err" && [ "${CI:-}" != true ]; then
      echo "== skipping $a: $(head -1 "$w/prepare.err")"
      return 1
    fi
    cat "$w/prepare.err" >&2
    exit 1
  fi
}
