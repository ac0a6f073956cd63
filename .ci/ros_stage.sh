#!/usr/bin/env bash
# CI, ROS stage (issue 17): build the package with colcon against the shared ROS 2 Jazzy in a
# temporary workspace, then run its ROS tests through ament (`colcon test`): the node tests
# (test/nodes, rclpy in-process) and the live tests (test/ros_live: ros2 launch, ros2 bag
# play/record, services, SIGKILL and restart). `colcon test-result --verbose` reports them and
# fails the stage on a failure. Without ../shared/ros2 the stage is skipped with a note.
# Runs with the Python of the caller (.ci/run: its venv with the project's dependencies).
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$PWD
ros_dir=../shared/ros2
started=$(date +%s)
if [ ! -f "$ros_dir/install.sh" ]; then
  echo "ROS stage SKIPPED: $ros_dir/install.sh not found, so there is no ROS 2 Jazzy to build and test against."
  exit 0
fi

echo "== ROS stage: install ROS 2 Jazzy from $ros_dir"
setup=$(bash "$ros_dir/install.sh" | sed -n 's/^source //p' | tail -1)
# setup.bash reads unset variables.
set +u
# shellcheck disable=SC1090
source "$setup"
set -u
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
unset ROS_LOCALHOST_ONLY
# One domain for this run's tests (0-101: the range of the default DDS ports); CI runs alone.
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-$((17 + $$ % 24))}
export ROBOCAL_LIVE_DOMAIN_ID=$ROS_DOMAIN_ID ROBOCAL_TEST_DOMAIN_ID=$ROS_DOMAIN_ID

if ! python -c "import colcon_core" 2>/dev/null; then
  python -m pip install --quiet colcon-common-extensions
fi
colcon() { python -c 'import sys; from colcon_core.command import main; sys.exit(main())' "$@"; }

ws=$(mktemp -d)
cleanup() {
  ros2 daemon stop >/dev/null 2>&1 || true
  rm -rf "$ws"
}
trap cleanup EXIT
mkdir "$ws/src"
ln -s "$repo" "$ws/src/robocal_uncertainty"
cd "$ws"

echo "== ROS stage: colcon build in $ws (domain $ROS_DOMAIN_ID)"
colcon build --event-handlers console_cohesion+ --cmake-args -DBUILD_TESTING=ON
set +u
# shellcheck disable=SC1091
source install/setup.bash
set -u
built=$(date +%s)

echo "== ROS stage: colcon test (ament: test/nodes and test/ros_live, label ros)"
colcon test --event-handlers console_direct+ --ctest-args -L '^ros$'
colcon test-result --verbose
ros2 daemon stop >/dev/null 2>&1 || true
echo "ROS stage passed: build $((built - started)) s, tests $(($(date +%s) - built)) s, total $(($(date +%s) - started)) s"
