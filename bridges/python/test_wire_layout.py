"""The ctypes mirror matches the Rust wire types: size, alignment, type name, field offsets.

Runs `cargo run -p concord-ipc --example wire_layout` for the Rust side, or reads the JSON it
prints from $CONCORD_WIRE_LAYOUT.
"""

import ctypes
import json
import os
import subprocess
import unittest

import concord_wire as wire

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))


def rust_layout():
    path = os.environ.get("CONCORD_WIRE_LAYOUT")
    if path:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    out = subprocess.run(["cargo", "run", "--quiet", "-p", "concord-ipc", "--example", "wire_layout"],
                         cwd=ROOT, check=True, capture_output=True, text=True).stdout
    return json.loads(out)


class WireLayout(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.rust = rust_layout()

    def test_every_rust_type_has_a_mirror_and_back(self):
        self.assertEqual(sorted(self.rust), sorted(t.__name__ for t in wire.ALL_TYPES))

    def test_sizes_alignments_names_and_offsets_match(self):
        for ty in wire.ALL_TYPES:
            with self.subTest(type=ty.__name__):
                r = self.rust[ty.__name__]
                self.assertEqual(ctypes.sizeof(ty), r["size"], "size")
                self.assertEqual(ctypes.alignment(ty), r["align"], "alignment")
                self.assertEqual(ty.type_name(), r["type_name"], "type name")
                mirror = {name: getattr(ty, name).offset for name, _ in ty._fields_}
                self.assertEqual(mirror, r["fields"], "field offsets")

    def test_text_round_trip_cuts_at_a_character_boundary(self):
        m = wire.IntentText()
        wire.set_text(m, "é" * 200)  # 400 bytes: cut to 256, an even number of bytes
        self.assertEqual(m.len, 256)
        self.assertEqual(wire.text_of(m), "é" * 128)


if __name__ == "__main__":
    unittest.main()
