#!/usr/bin/env bash
# Rebuilds paper.net.xml, the paper's junction as a SUMO network, from its plain XML sources
# (and ../opendrive/paper.xodr from it),
# with the netconvert of the pinned eclipse-sumo wheel (bridges/python/setup.sh installs it).
# The network is shipped, so nothing runs this at setup.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
python="${PYTHON:-$here/../../../.venv/bin/python}"
netconvert="$("$python" -c 'import sumo, os; print(os.path.join(sumo.SUMO_HOME, "bin", "netconvert"))')"
cd "$here"
"$netconvert" --node-files paper.nod.xml --edge-files paper.edg.xml \
    --no-turnarounds true --offset.disable-normalization true --output-file paper.net.xml
# The same junction as OpenDRIVE, for the Rust OpenDRIVE reader (map/src/opendrive.rs).
mkdir -p ../opendrive
"$netconvert" --sumo-net-file paper.net.xml --opendrive-output ../opendrive/paper.xodr
