"""The ctypes mirror matches the Rust wire types: size, alignment, type name, field offsets and
field types; and its name tuples name the Rust enums' codes in order.

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

# ctypes scalars in Rust's notation (c_ubyte is c_uint8, c_byte is c_int8).
SCALARS = {
    ctypes.c_double: "f64", ctypes.c_float: "f32",
    ctypes.c_uint64: "u64", ctypes.c_int64: "i64",
    ctypes.c_uint32: "u32", ctypes.c_int32: "i32",
    ctypes.c_uint16: "u16", ctypes.c_int16: "i16",
    ctypes.c_uint8: "u8", ctypes.c_int8: "i8",
    ctypes.c_bool: "bool",
}


def rust_type(ctype):
    """A ctypes field type as Rust prints it: `f64`, `[u8; 7]`, `WireAgent`."""
    if ctype in SCALARS:
        return SCALARS[ctype]
    if issubclass(ctype, ctypes.Array):
        return f"[{rust_type(ctype._type_)}; {ctype._length_}]"
    if issubclass(ctype, ctypes.Structure):
        return ctype.__name__
    raise TypeError(f"no Rust notation for {ctype!r}")


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
        layout = rust_layout()
        cls.rust = layout["types"]
        cls.names = layout["names"]

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
                rust = {name: f["offset"] for name, f in r["fields"].items()}
                self.assertEqual(mirror, rust, "field offsets")

    def test_field_types_match(self):
        for ty in wire.ALL_TYPES:
            rust = self.rust[ty.__name__]["fields"]
            for name, ctype in ty._fields_:
                with self.subTest(type=ty.__name__, field=name):
                    self.assertIn(name, rust, f"{ty.__name__}.{name} is not a Rust field")
                    self.assertEqual(rust_type(ctype), rust[name]["type"],
                                     f"type of {ty.__name__}.{name}")

    def test_code_names_match(self):
        self.assertEqual(sorted(self.names), sorted(wire.CODE_NAMES))
        for rust_enum, names in wire.CODE_NAMES.items():
            with self.subTest(enum=rust_enum):
                self.assertEqual(list(names), self.names[rust_enum])

    def test_text_round_trip_cuts_at_a_character_boundary(self):
        m = wire.IntentText()
        wire.set_text(m, "é" * 200)  # 400 bytes: cut to 256, an even number of bytes
        self.assertEqual(m.len, 256)
        self.assertEqual(wire.text_of(m), "é" * 128)


if __name__ == "__main__":
    unittest.main()
