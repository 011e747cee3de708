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

# copy_scene AREA DIR: scenes/AREA.toml into DIR, the shared data's relative paths made absolute, for a
# benchmark that appends its own [sampling] tables; a scene file with [sampling] tables of its own is
# refused (they would clash).
copy_scene() {
  local a=$1 dir=$2 shared
  shared=$(realpath ../shared 2>/dev/null || echo ../shared)
  sed "s#\.\./\.\./shared#$shared#" "scenes/$a.toml" > "$dir/$a.toml"
  if grep -q '^\[sampling' "$dir/$a.toml"; then
    echo "scenes/$a.toml has [sampling] tables of its own; this benchmark writes its own" >&2
    exit 1
  fi
}
