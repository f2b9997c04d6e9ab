# Sourced by the search table scripts: the agvrl binary, `key`, and the 16 held-out rows.
#   search_rows FUNCTION: for every scene, maps and noise preset, sets `row_args` to that row's
#   `agvrl eval` arguments (for $policy, $episodes and $seed, 1,000 steps) and calls
#   FUNCTION ENV LAYOUTS PRESET.
bin="${AGVRL:-${CARGO_TARGET_DIR:-target}/release/agvrl}"
[ -x "$bin" ] || cargo build --release -q
key() { sed -n "s/^$1=//p" <<<"$2"; }
search_rows() {
  local preset layouts env
  for preset in none sim2real; do
    for layouts in builtin procedural; do
      for env in search-outdoor-20 search-urban-20 search-outdoor-50 search-urban-50; do
        row_args=(eval --policy "$policy" --env "$env" --episodes "$episodes" --seed "$seed" --layouts "$layouts" --max-steps 1000)
        [ "$preset" = none ] || row_args+=(--preset "$preset")
        "$1" "$env" "$layouts" "$preset"
      done
    done
  done
}
