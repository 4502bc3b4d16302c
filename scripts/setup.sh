#!/usr/bin/env bash
# Installs the Debian packages a command needs, and nothing else. Idempotent: when everything
# is installed it only checks (about a second) and touches no network.
#
#   scripts/setup.sh            build and run catpaq (the demo): scripts/packages.txt
#   scripts/setup.sh --tests    also the tests and the evaluation report: scripts/packages-test.txt
#   scripts/setup.sh --bench    also the server benchmark: scripts/packages-bench.txt (implies --tests)
#
# It never touches the machine's services: nothing is stopped, disabled or killed. A package that
# would start a service when installed (nginx-light, for the benchmark, which runs nginx under
# its own configuration) is installed with service starts denied for that install only
# (policy-rc.d), unless the machine already has a policy of its own.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
lists=("$here/packages.txt")
for arg in "$@"; do
  case "$arg" in
    --tests) lists+=("$here/packages-test.txt") ;;
    --bench) lists+=("$here/packages-test.txt" "$here/packages-bench.txt") ;;
    -h|--help) sed -n '2,12p' "$0"; exit 0 ;;
    *) echo "setup: unknown option $arg (see --help)" >&2; exit 2 ;;
  esac
done
mapfile -t pkgs < <(cat "${lists[@]}" | grep -v '^\s*#' | grep -v '^\s*$' | sort -u)

missing=()
for p in "${pkgs[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed'; then
    missing+=("$p")
  fi
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "setup: all ${#pkgs[@]} packages present"
  exit 0
fi

sudo=""
if [ "$(id -u)" != 0 ]; then
  command -v sudo >/dev/null || { echo "setup: need root (or sudo) to install: ${missing[*]}" >&2; exit 1; }
  sudo="sudo"
fi
echo "setup: installing ${#missing[@]} packages: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
policy=/usr/sbin/policy-rc.d
deny_starts=0
if [ ! -e "$policy" ]; then
  # Exit status 101: "action forbidden" for every service start the installs ask for.
  printf '#!/bin/sh\n# written by catpaq scripts/setup.sh for one install; removed after it\nexit 101\n' |
    $sudo tee "$policy" >/dev/null
  $sudo chmod 755 "$policy"
  deny_starts=1
  trap '$sudo rm -f "$policy"' EXIT
fi
$sudo apt-get update -qq
$sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
if [ "$deny_starts" = 1 ]; then $sudo rm -f "$policy"; trap - EXIT; fi
echo "setup: done"
