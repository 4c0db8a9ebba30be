#!/usr/bin/env bash
# install-deps.sh -- install every Debian package luxrad's build, tests and
# tools need, on a fresh Debian bookworm machine.
#
# Idempotent and fast when nothing is missing: each package is checked with
# dpkg-query first, and apt-get (update + install) runs only for what is
# absent, so a second run touches no network.  Works as root; otherwise it
# goes through sudo when present and fails with a clear message if not.
#
# Every package listed is required: a package that cannot be installed is
# an error, never a silent skip.
set -euo pipefail

# Build: compiler, CMake + Ninja, pkg-config (jansson, cmocka), formatter.
# Engine and tools: Embree (BVH, pulls libtbb-dev), tinygltf, jansson;
# libpng and libjpeg-turbo decode base-colour textures.
# Daemon and its tests: libmodbus, SQLite, cmocka; real Modbus peers
# (mbpoll, pymodbus) for end-to-end tests; gnuplot for the study plots;
# python3 validates JSON in the CLI test, with numpy and Pillow reads
# textures independently in test_textures; Node.js + npm run the Khronos
# glTF validator; Blender (with its bundled glTF exporter) makes the
# scenes test_blender and tests/bench/textured_interior.sh export at run
# time.
# libssl-dev: OpenSSL, for TLS on the protocol listener and the users'
# token hashes (SHA-256); openssl, the command, makes test_daemon_tls's
# certificates and is its s_client.
# python3-serial-asyncio is only a Recommends of python3-pymodbus, but
# `import pymodbus.client` fails without it, so it is listed explicitly.
# The fuzz stage builds with clang; libclang-rt-dev brings the runtime
# libraries of its -fsanitize=fuzzer,address,undefined (libclang-rt-14-dev
# on bookworm: libclang_rt.fuzzer and the sanitizers).
PACKAGES=(
	build-essential cmake ninja-build pkg-config clang-format
	clang libclang-rt-dev
	libembree-dev libtinygltf-dev libmodbus-dev libcmocka-dev
	libjansson-dev libsqlite3-dev libpng-dev libjpeg62-turbo-dev libssl-dev
	openssl
	mbpoll gnuplot-nox python3 python3-pymodbus python3-serial-asyncio
	python3-numpy python3-pil
	nodejs npm chromium blender
)

log() { printf 'install-deps: %s\n' "$*" >&2; }

# True if dpkg knows the package as fully installed.
installed() {
	local status
	status=$(dpkg-query -W -f='${Status}' "$1" 2>/dev/null) || return 1
	[[ $status == "install ok installed" ]]
}

# Some machines carry Node.js from another archive whose nodejs package
# bundles npm and conflicts with Debian's npm; a working `npm` command is
# what the tests need, so it counts as installed whatever package gave it.
satisfied() {
	case $1 in
	npm) command -v npm >/dev/null 2>&1 && return 0 ;;
	esac
	installed "$1"
}

# Run a command as root: directly, through sudo, or not at all.
as_root() {
	if [[ $(id -u) -eq 0 ]]; then
		"$@"
	elif command -v sudo >/dev/null 2>&1; then
		sudo "$@"
	else
		log "not root and sudo is not installed: cannot run '$*'"
		log "run this script as root, or install sudo"
		exit 1
	fi
}

# The Khronos glTF validator (npm package gltf-validator) for the export
# tests: installed into tests/tools/node_modules, exactly the version that
# tests/tools/package-lock.json pins, with `npm ci` (no global install, no
# root).  Skipped when that version is already there, so a second run
# touches no network.
# The gltf-validator version installed under $1/node_modules, or "".
pinned_have() {
	node -p "require(process.argv[1]).version" \
		"$1/node_modules/gltf-validator/package.json" 2>/dev/null || true
}

install_validator() {
	local dir want have
	dir="$(cd "$(dirname "$0")/.." && pwd)/tests/tools"
	want=$(node -p "require(process.argv[1]).packages['node_modules/gltf-validator'].version" \
		"$dir/package-lock.json") || {
		log "cannot read the pinned gltf-validator version from $dir/package-lock.json"
		exit 1
	}
	have=$(pinned_have "$dir")
	if [[ $have == "$want" ]]; then
		log "gltf-validator $want present"
		return 0
	fi
	log "installing gltf-validator $want into $dir/node_modules"
	npm ci --prefix "$dir" --no-audit --no-fund --loglevel=error
	have=$(pinned_have "$dir")
	if [[ $have != "$want" ]]; then
		log "gltf-validator $want still missing after npm ci"
		exit 1
	fi
}

main() {
	local missing=() p
	for p in "${PACKAGES[@]}"; do
		satisfied "$p" || missing+=("$p")
	done
	if [[ ${#missing[@]} -eq 0 ]]; then
		log "all ${#PACKAGES[@]} packages present"
		install_validator
		return 0
	fi
	log "installing: ${missing[*]}"
	# The package lists of a fresh machine may be empty or stale, so
	# refresh them, but only when something has to be installed.
	as_root env DEBIAN_FRONTEND=noninteractive apt-get update -q
	as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q \
		"${missing[@]}" </dev/null
	for p in "${missing[@]}"; do
		if ! satisfied "$p"; then
			log "package $p still missing after apt-get install"
			exit 1
		fi
	done
	install_validator
	log "done"
}

main "$@"
