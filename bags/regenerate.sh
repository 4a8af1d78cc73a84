#!/usr/bin/env bash
# Re-mints the committed twin data of bags/ from bags/recipes.txt with the current build (the
# bag writer never overwrites, so each output goes first). Run from anywhere; then
# `cargo test --test it bag_` checks them against the twin's truth and the formats.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
rpkm=target/release/rpkm
grep -v '^#' bags/recipes.txt | while read -r out truth args; do
    [ -n "$out" ] || continue
    case "$out" in
        *.csv) rm -f "bags/$out" "bags/${out%.csv}.val.csv" ;;
        *) rm -rf "bags/$out" "bags/${out}_val" ;;
    esac
    rm -f "bags/$truth"
    echo "rpkm simulate $args --out bags/$out --truth bags/$truth"
    # shellcheck disable=SC2086 # the recipe's arguments are words
    "$rpkm" simulate $args --out "bags/$out" --truth "bags/$truth"
done
