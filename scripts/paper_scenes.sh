# Sourced by the benchmark scripts (bench_update.sh, bench_packets.sh): make_scene NAME writes
# $SCENE_DIR/NAME.json, the paper's scenes and the others of the tables, unless it exists. Needs
# DUPLEX (the tool), DATA (../shared/data/meshes) and SCENE_DIR.
#
#   paper-1   koala split into 19 objects
#   paper-2   koala split into 6,804 objects
#   paper-3   koala refined once by Loop subdivision, split into 20,968 objects
#   robot5    the ABB IRB 6640 (9 parts placed by its URDF), 5 copies
#   hammer1k  1,000 randomly rotated instances of the hammer
make_scene() {
  local name=$1 out=$SCENE_DIR/$1.json
  [ -f "$out" ] && return
  case "$name" in
    paper-1) "$DUPLEX" scene split --mesh "$DATA/koala.obj" --objects 19 --out "$out" ;;
    paper-2) "$DUPLEX" scene split --mesh "$DATA/koala.obj" --objects 6804 --out "$out" ;;
    paper-3) "$DUPLEX" scene split --mesh "$DATA/koala.obj" --loop 1 --objects 20968 --out "$out" ;;
    robot5) "$DUPLEX" scene robot --urdf "$DATA/abb_irb6640/irb6640.urdf" --copies 5 --out "$out" ;;
    hammer1k) "$DUPLEX" scene instances --mesh "$DATA/hammer.obj" --count 1000 --seed 1 --out "$out" ;;
    *) echo "unknown scene $name" >&2; exit 2 ;;
  esac >/dev/null
}
