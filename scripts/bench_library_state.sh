# Sourced by scripts/bench_run.sh and scripts/bench_callgrind.sh (needs $ROOT).
# What is about to be compiled: revision, plus a hash of uncommitted changes in accel/ and objects/
# (the library is edited while we measure; the bench stores this in machine.duplex_library_at_build).
library_state() {
  (
    cd "$ROOT" || exit 0
    local rev
    rev=$(git rev-parse --short HEAD 2>/dev/null || echo unknown)
    if [ -z "$(git status --porcelain -- accel objects 2>/dev/null)" ]; then
      echo "$rev"
    else
      echo "$rev+dirty:$({ git diff HEAD -- accel objects
                           git ls-files --others --exclude-standard -- accel objects | xargs -r git hash-object
                         } 2>/dev/null | sha1sum | cut -c1-10)"
    fi
  )
}
export DUPLEX_BENCH_BUILD_INFO=$(library_state)
