#!/usr/bin/env bash
# check_doc_refs.sh -- fail when the project cites a design document, or a
# numbered section of one, that does not exist.
#
# Usage: check_doc_refs.sh REPO_ROOT   (run by CTest as test_doc_refs)
#
# Scans the text files under daemon, protocol, client, scenes, tests,
# deploy and docs, and README.md, for these references:
#   - a path ending in docs/NAME.md, optionally followed by a section
#     sign and a number N (1, 4.3, ...): REPO_ROOT/docs/NAME.md must
#     exist, nothing may come before docs/ (a path into another tree, such
#     as the research folder beside the clone, is not the project's), and
#     N must be the number of a Markdown heading of that file;
#   - any other path DIR/NAME.md followed by a section sign and N: the
#     file must exist at that path from REPO_ROOT and have heading N;
#   - a NAME.md with no directory, followed by a section sign and N: it is
#     docs/NAME.md if that exists, else the one file of that name in the
#     tree, and N must be one of its headings;
#   - in docs/NAME.md itself, a section sign and N with no file name
#     before it is a cross-reference within NAME.md, unless "report"
#     comes before it (the sections of the study the docs restate).
# A heading numbered N starts with #s, then N, an optional dot and a
# space ("## 4. Title", "### 4.3 Title").
#
# So that the check cannot pass by finding nothing, it first runs on a
# scratch tree with three good and six bad references and must accept
# the first three and report exactly the six others, and it fails when the
# project holds no reference at all.
#
# Exit status: 0 every reference resolves; 1 some do not (each printed as
# FILE:LINE: reference: reason); 2 usage, or the self-check failed.
set -u
export LC_ALL=C

ROOT=${1:?usage: check_doc_refs.sh REPO_ROOT}
SELF=$(basename "$0")
SECT='§[0-9]+(\.[0-9]+)*'
# docs/NAME.md with whatever path characters precede it, then a section.
PATH_REF="[A-Za-z0-9_./~-]*docs/[A-Za-z0-9_-]+\\.md(\`?[ ]*$SECT)?"
# Any path to a .md file, then a section (docs/ ones are PATH_REF's).
DIR_REF="[A-Za-z0-9_.~-][A-Za-z0-9_./~-]*/[A-Za-z0-9_-]+\\.md\`?[ ]*$SECT"
# NAME.md not preceded by a path character, then a section.
BARE_REF="(^|[^A-Za-z0-9_./~-])[A-Za-z0-9_-]+\\.md\`?[ ]*$SECT"
# In docs/: a section with neither a file name nor "report" before it.
SELF_REF='(?<![Rr]eport )(?<!\.md )(?<!\.md` )§[0-9]+(?:\.[0-9]+)*'

# The section number in a match, or nothing.
section_of() {
	grep -oE "$SECT" <<<"$1" | head -n 1 | sed 's/^§//'
}

# 0 if Markdown file $1 has a heading numbered $2.
has_heading() {
	local num=${2//./\\.}
	grep -qE "^#{1,6}[[:space:]]+(§)?$num\\.?([[:space:]]|$)" "$1"
}

# The file a bare NAME.md means under root $1, or nothing if not unique.
resolve_bare() {
	local root=$1 name=$2 found
	if [ -f "$root/docs/$name" ]; then
		echo "$root/docs/$name"
		return
	fi
	found=$(find "$root" -name node_modules -prune -o -name .git -prune \
		-o -path "$root/build*" -prune -o -type f -name "$name" -print)
	[ "$(grep -c . <<<"$found")" = 1 ] && echo "$found"
}

# grep -rnoE pattern $2 over the scanned part of root $1.
scan_grep() {
	local root=$1 pattern=$2 where=() d
	for d in daemon protocol client scenes tests deploy docs README.md; do
		[ -e "$root/$d" ] && where+=("$root/$d")
	done
	[ ${#where[@]} -gt 0 ] || return 0
	grep -rHnoIE --exclude-dir=node_modules --exclude-dir=out \
		--exclude-dir=generated --exclude-dir=.git \
		--exclude="$SELF" -e "$pattern" "${where[@]}"
}

# Take one grep hit FILE:LINE:MATCH under root $2: sets HIT_FILE, HIT_LOC
# (FILE:LINE, relative to the root) and HIT_REF, and counts it.
take_hit() {
	local rest=${1#*:}
	HIT_FILE=${1%%:*}
	HIT_LOC="${HIT_FILE#"$2"/}:${rest%%:*}"
	HIT_REF=${rest#*:}
	NREFS=$((NREFS + 1))
}

# Report the current hit as not resolving, and why.
bad() {
	echo "$HIT_LOC: $HIT_REF: $1"
	NBAD=$((NBAD + 1))
}

# The first NAME.md in $1.
md_name() {
	grep -oE '[A-Za-z0-9_-]+\.md' <<<"$1" | head -n 1
}

# A path ending in docs/NAME.md, with or without a section; root $1.
check_path_ref() {
	local name sec
	name=$(md_name "$HIT_REF")
	sec=$(section_of "$HIT_REF")
	if [ "${HIT_REF%%docs/*}" != "" ]; then
		bad "not the project's docs/ (path before docs/)"
	elif [ ! -f "$1/docs/$name" ]; then
		bad "docs/$name does not exist"
	elif [ -n "$sec" ] && ! has_heading "$1/docs/$name" "$sec"; then
		bad "docs/$name has no section §$sec"
	fi
}

# A path DIR/NAME.md and a section, outside docs/; root $1.
check_dir_ref() {
	local path
	path=$(grep -oE '^[A-Za-z0-9_./~-]+\.md' <<<"$HIT_REF")
	if [ ! -f "$1/$path" ]; then
		bad "$path does not exist"
	elif ! has_heading "$1/$path" "$(section_of "$HIT_REF")"; then
		bad "$path has no such section"
	fi
}

# A bare NAME.md and a section; root $1.
check_bare_ref() {
	local target
	HIT_REF=${HIT_REF#[^A-Za-z0-9_-]}
	target=$(resolve_bare "$1" "$(md_name "$HIT_REF")")
	if [ -z "$target" ]; then
		bad "no single $(md_name "$HIT_REF") in the project"
	elif ! has_heading "$target" "$(section_of "$HIT_REF")"; then
		bad "${target#"$1"/} has no such section"
	fi
}

# A section alone, in the docs file HIT_FILE itself; root $1.
check_self_ref() {
	has_heading "$HIT_FILE" "$(section_of "$HIT_REF")" ||
		bad "no such section in ${HIT_FILE#"$1"/}"
}

# Run check $2 on every grep hit read from standard input; root $1.
each_hit() {
	local line
	while IFS= read -r line; do
		take_hit "$line" "$1"
		"$2" "$1"
	done
}

# Check every reference under root $1: prints problems, sets NREFS and
# NBAD.
check_tree() {
	NREFS=0
	NBAD=0
	each_hit "$1" check_path_ref < <(scan_grep "$1" "$PATH_REF")
	each_hit "$1" check_dir_ref < <(scan_grep "$1" "$DIR_REF" |
		grep -vE "docs/[A-Za-z0-9_-]+\\.md\`?[ ]*$SECT\$")
	each_hit "$1" check_bare_ref < <(scan_grep "$1" "$BARE_REF")
	each_hit "$1" check_self_ref < <(find "$1/docs" -maxdepth 1 \
		-name '*.md' -type f -exec grep -HnoP "$SELF_REF" {} + 2>/dev/null)
}

# The self-check: a scratch tree whose three good references must pass
# and whose six bad ones must each be reported.
TMP=$(mktemp -d "${TMPDIR:-/tmp}/luxrad-docrefs.XXXXXX") || exit 2
trap 'rm -rf "$TMP"' EXIT
mkdir -p "$TMP/docs" "$TMP/daemon"
printf '# T\n\n## 1. One\n\nSee §1.2, not report §7.\n\n### 1.2 Two\n' \
	>"$TMP/docs/GOOD.md"
printf '/* see docs/GOOD.md §1.2, daemon/X.md §1 */\n' >"$TMP/daemon/a.c"
printf '## 1 X\n' >"$TMP/daemon/X.md"
check_tree "$TMP" >"$TMP/out"
if [ "$NBAD" != 0 ] || [ "$NREFS" != 3 ]; then
	echo "self-check: a good reference was refused or missed:" >&2
	cat "$TMP/out" >&2
	exit 2
fi
{
	printf '/* docs/GOOD.md §3 and docs/MISSING.md */\n'
	printf '/* shared/docs/GOOD.md, GOOD.md §1.3, daemon/X.md §2 */\n'
} >"$TMP/daemon/b.c"
printf 'And §3.\n' >>"$TMP/docs/GOOD.md"
check_tree "$TMP" >"$TMP/out"
if [ "$NBAD" != 6 ]; then
	echo "self-check: expected 6 bad references, found $NBAD:" >&2
	cat "$TMP/out" >&2
	exit 2
fi

check_tree "$ROOT"
if [ "$NREFS" = 0 ]; then
	echo "no docs reference found under $ROOT: is the pattern broken?" >&2
	exit 2
fi
if [ "$NBAD" != 0 ]; then
	echo "$NBAD of $NREFS docs references do not resolve" >&2
	exit 1
fi
echo "$NREFS docs references resolve"
