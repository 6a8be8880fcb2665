#!/usr/bin/env bash
# Regenerate every file in sample_logs/ with `dracc simulate` (deterministic: same seed,
# same bytes).  Run from anywhere with dracc installed:  sample_logs/make_samples.sh
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

# The demo voyage: 3 h, four legs, gyro and magnetic compass, current, three INS, GNSS.
# Rates lowered to keep the folder small: compasses every 5 s, everything else every 30 s.
r30=0.0333333333333
voyage=(--hours 3 --seed 9 --start 2026-03-01T06:00:00Z --compass both
        --legs 0:60,2700:150,5400:30,8100:285
        --compass-hz 0.2 --log-hz $r30 --aux-hz $r30 --ins-hz $r30 --gnss-hz $r30 --truth-hz $r30)

dracc simulate "${voyage[@]}" --format nmea --form tag --name voyage_tag --out "$tmp/tag"
# without TAG blocks the three INS are told apart by their talkers
dracc simulate "${voyage[@]}" --format nmea --form prefix --ins-talkers II,IN,IR \
    --name voyage_prefix --out "$tmp/prefix"
dracc simulate "${voyage[@]}" --format csv-long --name voyage_long --out "$tmp/long"
dracc simulate "${voyage[@]}" --format csv-wide --name voyage_wide --out "$tmp/wide"
dracc simulate "${voyage[@]}" --format mcap-json --name voyage --out "$tmp/mcap"

# every run simulated the same voyage: the truth must be identical
for d in prefix long wide mcap; do
    cmp -s "$tmp/tag/truth.csv" "$tmp/$d/truth.csv" || { echo "truth differs in $d" >&2; exit 1; }
    cmp -s "$tmp/tag/errors.csv" "$tmp/$d/errors.csv" || { echo "errors differ in $d" >&2; exit 1; }
done

cp "$tmp/tag/voyage_tag.nmea" "$tmp/prefix/voyage_prefix.nmea" "$tmp/long/voyage_long.csv" \
   "$tmp/wide/voyage_wide.csv" "$tmp/mcap/voyage.mcap" \
   "$tmp/tag/truth.csv" "$tmp/tag/errors.csv" "$tmp/tag/params.json" "$here/"
chmod 644 "$here"/voyage_* "$here"/voyage.mcap "$here"/truth.csv "$here"/errors.csv "$here"/params.json
# A day at sea (26 h, so that a whole UTC day of hourly instants is covered): the INS
# statistics need many instants.  Rates lowered further: compass every 10 s, the rest
# every minute.  Only the MCAP log and its parameters are kept (truth: rerun this script).
r60=0.0166666666667
dracc simulate --hours 26 --seed 11 --start 2026-03-01T00:00:00Z --compass gyro \
    --compass-hz 0.1 --log-hz $r60 --aux-hz 0 --ins-hz $r60 --gnss-hz $r60 --truth-hz $r60 \
    --format mcap-json --name voyage_day --out "$tmp/day"
mkdir -p "$here/day"
cp "$tmp/day/voyage_day.mcap" "$tmp/day/params.json" "$here/day/"
chmod 644 "$here"/day/*
ls -l "$here" "$here/day"
