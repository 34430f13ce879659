# Sourced by the scripts that build a real person's avatar (real_person.sh,
# before_after.sh): their shared options. Set `iterations` and `name` first.
#   parse_person_args "$@"   sets general, iterations, video, ict; checks the inputs exist
parse_person_args() {
  general="" video=$data/video/talking_d9.mp4 ict=$data/head-models/ict-facekit
  while [ $# -gt 0 ]; do
    case $1 in
      --general) general=$2; shift 2 ;;
      --iterations) iterations=$2; shift 2 ;;
      --video) video=$2; shift 2 ;;
      --ict) ict=$2; shift 2 ;;
      *) echo "$name: unknown option $1" >&2; exit 2 ;;
    esac
  done
  [ -f "$video" ] || { echo "$name: no video $video" >&2; exit 2; }
  [ -d "$ict" ] || { echo "$name: no ICT-FaceKit folder $ict" >&2; exit 2; }
}
