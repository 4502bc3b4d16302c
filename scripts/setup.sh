#!/usr/bin/env bash
# Installs the Debian packages a command needs, and nothing else. Idempotent: when everything
# is installed it only checks (about a second) and touches no network.
#
#   scripts/setup.sh            build and run catpaq (the demo): scripts/packages.txt
#   scripts/setup.sh --tests    also the tests and the evaluation report: scripts/packages-test.txt,
#                               and npm's laz-perf@0.0.7 (the independent LAZ decoder that checks
#                               the benchmark's LAZ files) in $CATPAQ_NPM_DIR (~/.cache/catpaq-npm)
#   scripts/setup.sh --bench    also the server benchmark: scripts/packages-bench.txt (implies --tests)
#
# It never touches the machine's services: nothing is stopped, disabled or killed. A package that
# would start a service when installed (nginx-light, for the benchmark, which runs nginx under
# its own configuration) is installed with service starts denied for that install only
# (policy-rc.d), unless the machine already has a policy of its own.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
lists=("$here/packages.txt")
npm_packages=0
for arg in "$@"; do
  case "$arg" in
    --tests) lists+=("$here/packages-test.txt"); npm_packages=1 ;;
    --bench) lists+=("$here/packages-test.txt" "$here/packages-bench.txt"); npm_packages=1 ;;
    -h|--help) sed -n '2,14p' "$0"; exit 0 ;;
    *) echo "setup: unknown option $arg (see --help)" >&2; exit 2 ;;
  esac
done
mapfile -t pkgs < <(cat "${lists[@]}" | grep -v '^\s*#' | grep -v '^\s*$' | sort -u)

# npm's packages, after Debian's (npm comes from there): laz-perf into a fixed directory outside
# the repository, where scripts/report/laz_decode.mjs and the tests look (or $CATPAQ_NPM_DIR).
# Idempotent: present in the wanted version, it touches no network.
install_npm_packages() {
  [ "$npm_packages" = 1 ] || return 0
  local home="${HOME:-}"
  [ -n "$home" ] || home=$(getent passwd "$(id -u)" | cut -d: -f6)
  local dir="${CATPAQ_NPM_DIR:-$home/.cache/catpaq-npm}" want=0.0.7 have
  have=$(node -p "require('$dir/node_modules/laz-perf/package.json').version" 2>/dev/null || true)
  if [ "$have" = "$want" ]; then
    echo "setup: npm laz-perf $want present in $dir"
    return 0
  fi
  echo "setup: installing npm laz-perf@$want into $dir"
  mkdir -p "$dir"
  npm install --prefix "$dir" --no-audit --no-fund --loglevel=error "laz-perf@$want" >/dev/null
  have=$(node -p "require('$dir/node_modules/laz-perf/package.json').version" 2>/dev/null || true)
  [ "$have" = "$want" ] || { echo "setup: npm did not install laz-perf@$want into $dir" >&2; exit 1; }
}

# A package counts as present when installed, or provided by an installed package (nodejs from
# another repository provides npm, and conflicts with Debian's).
provided=$(dpkg-query -W -f='${Status}\t${Provides}\n' 2>/dev/null | grep '^install ok installed' | cut -f2 |
  tr ',' '\n' | sed 's/([^)]*)//g; s/ //g' | grep -v '^$' | sort -u || true)
missing=()
for p in "${pkgs[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' &&
     ! grep -qxF "$p" <<<"$provided"; then
    missing+=("$p")
  fi
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "setup: all ${#pkgs[@]} packages present"
  install_npm_packages
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
install_npm_packages
echo "setup: done"
