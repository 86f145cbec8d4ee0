#!/usr/bin/env bash
# The doors between the rooms, checked on the sources: every project #include of a file in folder
# F must name a folder F may use (docs/map.md). A room reaching above itself (the MT-file library
# including the patch store, a reader tool including the builder) fails with the file and line.
#   tests/check_doors.sh [REPO_ROOT]
# The rules: FOLDER: folders it may include (its own always allowed). Files of tools/ are split:
# the MT-file readers may not use the build side.
set -euo pipefail
root="${1:-$(cd "$(dirname "$0")/.." && pwd)}"
cd "$root"
declare -A allowed=(
  [base]=""
  [texture]="base"
  [patchstore/io]="base"
  [patchstore]="base texture patchstore/io patchstore/heal"
  [patchstore/heal]="base texture patchstore/io patchstore"
  [vpartition]="base patchstore/io patchstore"
  [mtfile]="base"
  [mtbuild]="base texture mtfile patchstore/io patchstore patchstore/heal vpartition"
  [cluster]="base mtfile patchstore/io patchstore vpartition mtbuild tools"
  [mtrender]="base texture mtfile"
  [interop]="base mtfile"
  [testing]="base texture mtfile patchstore/io patchstore vpartition mtbuild"
  [web/wasm]="mtfile"
)
readers="mtinfo mtverify mtextract mtexport"
reader_allowed="base texture mtfile patchstore/io interop tools"
bad=0 checked=0
check() {  # file folder allowed-list
  local file="$1" folder="$2" list="$3" n inc dir
  while IFS=: read -r n inc; do
    dir="${inc%/*}"
    [[ "$dir" == "$inc" ]] && dir="."
    checked=$((checked + 1))
    [[ "$dir" == "$folder" ]] && continue
    if [[ " $list " != *" $dir "* ]]; then
      echo "$file:$n: includes $inc, but $folder/ may use only: ${list:-nothing of ours}" >&2
      bad=$((bad + 1))
    fi
  done < <(grep -n '^[[:space:]]*#[[:space:]]*include[[:space:]]*"' "$file" | sed -E 's/^([0-9]+):[^"]*"([^"]*)".*/\1:\2/')
}
for folder in "${!allowed[@]}"; do
  [[ -d "$folder" ]] || continue
  while IFS= read -r f; do
    # A sub-folder with rules of its own is checked under those.
    sub="${f%/*}"
    [[ "$sub" != "$folder" && -n "${allowed[$sub]+x}" ]] && continue
    check "$f" "$folder" "${allowed[$folder]}"
  done < <(find "$folder" -name '*.h' -o -name '*.cpp' | sort)
done
for t in $readers; do
  [[ -f "tools/$t.cpp" ]] && check "tools/$t.cpp" tools "$reader_allowed"
done
[[ $checked -gt 100 ]] || { echo "check_doors: only $checked includes found under $root: wrong root?" >&2; exit 1; }
if [[ $bad -gt 0 ]]; then echo "check_doors: $bad includes through a door the design does not have" >&2; exit 1; fi
echo "check_doors: $checked includes, every one through an allowed door"
