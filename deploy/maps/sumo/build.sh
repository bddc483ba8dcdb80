#!/usr/bin/env bash
# Rebuilds the shipped SUMO networks from their plain XML sources (paper.net.xml: the paper's
# junction; corridor.net.xml: two junctions on one road) and the same networks as OpenDRIVE
# (../opendrive/*.xodr, for the Rust OpenDRIVE reader, map/src/opendrive.rs), with the
# netconvert of the pinned eclipse-sumo wheel (bridges/python/setup.sh installs it).
# The networks are shipped, so nothing runs this at setup.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
python="${PYTHON:-$here/../../../.venv/bin/python}"
netconvert="$("$python" -c 'import sumo, os; print(os.path.join(sumo.SUMO_HOME, "bin", "netconvert"))')"
cd "$here"
mkdir -p ../opendrive
for net in paper corridor; do
    "$netconvert" --node-files "$net.nod.xml" --edge-files "$net.edg.xml" \
        --no-turnarounds true --offset.disable-normalization true --output-file "$net.net.xml"
    "$netconvert" --sumo-net-file "$net.net.xml" --opendrive-output "../opendrive/$net.xodr"
done
