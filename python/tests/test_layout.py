"""The ctypes mirrors against the Rust layout.

Needs OILS_LAYOUT_JSON: the file `cargo run -p oils-shared --example layout_json` prints
(tools/python-e2e.sh makes it).
"""

import ctypes
import json
import os
import unittest

import oils_fsw.packets as p

SCALARS = {"u32": ctypes.c_uint32, "u64": ctypes.c_uint64, "i64": ctypes.c_int64, "f64": ctypes.c_double}


def load_rust_layout():
    with open(os.environ["OILS_LAYOUT_JSON"], encoding="utf-8") as f:
        return json.load(f)


class LayoutMatchesRust(unittest.TestCase):
    def setUp(self):
        self.rust = load_rust_layout()

    def test_schema_and_hash(self):
        self.assertEqual(p.SCHEMA, self.rust["schema"])
        self.assertEqual(p.SCHEMA_HASH, int(self.rust["schema_hash"], 16))
        self.assertEqual(p.fnv1a64(p.SCHEMA), p.SCHEMA_HASH)
        self.assertEqual(p.PROTOCOL_VERSION, self.rust["protocol_version"])

    def test_every_struct_size_offset_and_type(self):
        mirrored = 0
        for name, rust in self.rust["structs"].items():
            cls = getattr(p, name, None)
            if cls is None:
                self.assertEqual(name, "FswConfig", "only the C ABI's own struct has no mirror")
                continue
            mirrored += 1
            self.assertEqual(ctypes.sizeof(cls), rust["size"], name)
            self.assertEqual([f for f, _ in cls._fields_], list(rust["fields"]), name)
            for field, _ in cls._fields_:
                want = rust["fields"][field]
                self.assertEqual(getattr(cls, field).offset, want["offset"], f"{name}.{field}")
                self.assertEqual(getattr(cls, field).size, self.size_of(want["type"]), f"{name}.{field}")
        self.assertEqual(mirrored, 13)  # protocol v4: FrameAnnouncement is the thirteenth

    def size_of(self, ty: str) -> int:
        if ty.startswith("["):
            inner, n = ty[1:-1].split(";")
            return int(n) * self.size_of(inner)
        if ty in SCALARS:
            return ctypes.sizeof(SCALARS[ty])
        return self.rust["structs"][ty]["size"]

    def test_type_names_are_the_rust_ones(self):
        self.assertEqual(p.Telemetry.type_name(), "oils.v4.Telemetry")
        self.assertEqual(p.Command.type_name(), "oils.v4.Command")
        self.assertEqual(p.FrameAnnouncement.type_name(), "oils.v4.FrameAnnouncement")
        self.assertEqual(ctypes.alignment(p.Telemetry), 8)


if __name__ == "__main__":
    unittest.main()
