#!/usr/bin/env bash
# Runs a command in a network namespace of its own with only loopback (up, with multicast routed
# to it): DDS discovers its peers by multicast on every interface it finds, and no test traffic
# may leave this machine. Root makes the namespace directly; anyone else through a user namespace
# mapped to root.
#
#   scripts/in-netns.sh COMMAND [ARGS ...]
set -euo pipefail
[ $# -gt 0 ] || { echo "usage: scripts/in-netns.sh COMMAND [ARGS ...]" >&2; exit 2; }
NS=(unshare --net)
[ "$(id -u)" -ne 0 ] && NS=(unshare --net --map-root-user)
exec "${NS[@]}" -- sh -c '
  ip link set lo up &&
  ip link set lo multicast on &&
  ip route add 224.0.0.0/4 dev lo &&
  exec "$@"' sh "$@"
