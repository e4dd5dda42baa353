"""oils_fsw.data against the bench: a real log read with read_log equals the bench's own
CSV export of it, column for column, for a binary log and an MCAP log; a campaign
directory read with read_campaign agrees with its summary.

Needs OILS_BIN (the `oils` executable) and the ``data`` extra (numpy, pandas, mcap);
tools/python-e2e.sh sets both up. Values: integers and flags exactly; floats bit for bit
(NaN where the CSV has NaN), except the columns derived in the site frame (speeds,
tilt, site position and velocity), which numpy computes with its own sin, cos and acos:
those within 4 ulp or 1e-9 absolute (m, m/s, degrees), and the test reports how many
differ at all.
"""

import json
import struct
import os
import shutil
import subprocess
import tempfile
import unittest
import warnings
from pathlib import Path

try:
    import numpy as np
    import pandas as pd

    import oils_fsw
    from oils_fsw import data
except ImportError as e:  # the client alone, without the [data] extra
    NO_DATA = str(e)
else:
    NO_DATA = ""

OILS = os.environ.get("OILS_BIN")
NEEDS = "needs OILS_BIN and the [data] extra (tools/python-e2e.sh)"


def oils(*args, cwd):
    r = subprocess.run([OILS, *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=600)
    if r.returncode != 0:
        raise AssertionError(f"oils {' '.join(map(str, args))}: {r.stdout}\n{r.stderr}")
    return r


INTEGER_KINDS = {"u32": np.uint64, "u64": np.uint64, "hex": np.uint64, "i64": np.int64} if not NO_DATA else {}


def read_csv_exact(path, layout):
    """The bench's CSV, every number parsed exactly: integer columns (by the layout's
    kinds) as 64-bit integers, floats round trip (the default from pandas 3 on)."""
    exact = {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}
    ints = {c["name"]: INTEGER_KINDS[c["kind"]] for c in layout["columns"] if c["kind"] in INTEGER_KINDS}
    return pd.read_csv(path, dtype=ints, **exact)


def site_columns(layout):
    return {c["name"] for c in layout["columns"] if c.get("derive", {}).get("op") == "site"}


class DataExtraInstalled(unittest.TestCase):
    @unittest.skipUnless(os.environ.get("OILS_FSW_EXPECT_INSTALLED"), "run by tools/python-e2e.sh")
    def test_the_data_tests_run(self):
        # tools/python-e2e.sh installs ./python[data]: the tests below must not skip there.
        self.assertEqual(NO_DATA, "")
        self.assertTrue(OILS)


@unittest.skipIf(NO_DATA or not OILS, NO_DATA or NEEDS)
class LogsEqualTheCsvExport(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = Path(tempfile.mkdtemp(prefix="oils-data-"))
        cls.bin = cls.tmp / "binary.oilslog"
        cls.mcap = cls.tmp / "foxglove.mcap"
        oils("run", "--link", "inproc", "--duration", 20, "--log", cls.bin, cwd=cls.tmp)
        oils("run", "--link", "inproc", "--duration", 20, "--log", cls.mcap, "--log-format", "mcap", cwd=cls.tmp)
        for log in (cls.bin, cls.mcap):
            oils("export", log, "--csv", log.with_suffix(".csv"), cwd=cls.tmp)

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def assert_equals_csv(self, df, csv, layout):
        self.assertEqual(list(df.columns), list(csv.columns))
        self.assertEqual(len(df), len(csv))
        self.assertGreater(len(df), 1000)
        loose = site_columns(layout)
        self.assertTrue(loose, "the layout names its site-frame columns")
        differing = {}
        for name in csv.columns:
            got, want = df[name].to_numpy(), csv[name].to_numpy()
            if got.dtype.kind in "biu":
                self.assertIn(want.dtype.kind, "biu", f"{name}: integers in the log, {want.dtype} in the CSV")
                bad = np.nonzero(got.astype(np.uint64) != want.astype(np.uint64))[0]
                self.assertEqual(len(bad), 0, f"{name}: row {bad[:1]}: {got[bad[:1]]} != {want[bad[:1]]}")
                continue
            self.assertEqual(got.dtype, np.float64, name)
            want = want.astype(np.float64)
            same = (got.view(np.uint64) == want.view(np.uint64)) | (np.isnan(got) & np.isnan(want))
            if same.all():
                continue
            self.assertIn(name, loose, f"{name}: {np.count_nonzero(~same)} values differ from the CSV's bits")
            ulps = np.abs(got.view(np.int64) - want.view(np.int64))
            ok = (ulps <= 4) | (np.abs(got - want) <= 1e-9)
            self.assertTrue(ok.all(), f"{name}: off by up to {np.nanmax(np.abs(got - want))}")
            differing[name] = int(np.count_nonzero(~same))
        if differing:
            print(f"\n  site-frame columns not bit for bit (within tolerance): {differing}")

    def test_binary_log_equals_its_csv_export(self):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a complete log reads without a warning
            df = oils_fsw.read_log(self.bin)
        layout = data.read_layout(self.bin)
        self.assert_equals_csv(df, read_csv_exact(self.bin.with_suffix(".csv"), layout), layout)
        self.assertEqual(df["telemetry.header.step"].iloc[-1], len(df) - 1)
        self.assertIn("config", df.attrs["header"])

    def test_mcap_log_equals_its_csv_export(self):
        df = oils_fsw.read_log(self.mcap)
        layout = data.read_layout(self.mcap)
        self.assert_equals_csv(df, read_csv_exact(self.mcap.with_suffix(".csv"), layout), layout)

    def test_records_are_a_view_of_the_file(self):
        rec = data.read_records(self.bin)
        layout = data.read_layout(self.bin)
        self.assertEqual(rec.dtype.itemsize, layout["record_size"])
        self.assertFalse(rec.flags.owndata)
        stored = [c["name"] for c in layout["columns"] if "offset" in c]
        self.assertEqual(list(rec.dtype.names), stored)
        df = oils_fsw.read_log(self.bin)
        self.assertTrue(np.array_equal(rec["truth.altitude_m"], df["truth.altitude_m"].to_numpy()))

    def test_layout_file_reads_a_log_as_its_header_does(self):
        out = self.tmp / "layout.json"
        oils("export", self.bin, "--layout", out, cwd=self.tmp)
        self.assertEqual(json.loads(out.read_text()), data.read_layout(self.bin))
        a = data.read_log_arrays(self.bin)
        b = data.read_log_arrays(self.bin, layout=out)
        self.assertTrue(all(np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f") for k in a))

    def test_interrupted_log_reads_with_a_warning(self):
        cut = self.tmp / "cut.oilslog"
        raw = self.bin.read_bytes()
        layout = data.read_layout(self.bin)
        # The frames, by their headers (records u32, packed length u32, CRC).
        at, frames = 16 + int.from_bytes(raw[8:12], "little"), []
        hsize = layout["frames"]["header_size"]
        while at < len(raw) and raw[at:at + 8] != layout["trailer"]["magic"].encode():
            records, packed = struct.unpack_from("<II", raw, at)
            frames.append((at, records, hsize + packed))
            at += hsize + packed
        self.assertGreaterEqual(len(frames), 2)
        # Drop the trailer and half the last frame: as kill -9 mid-write leaves it.
        last_at, last_records, last_size = frames[-1]
        cut.write_bytes(raw[: last_at + last_size // 2])
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            df = oils_fsw.read_log(cut)
        said = " / ".join(str(w.message) for w in caught)
        full = oils_fsw.read_log(self.bin)
        self.assertEqual(len(df), len(full) - last_records)
        self.assertIn("without its trailer", said)
        self.assertIn(f"{last_size // 2} bytes after the last whole frame ignored", said)
        pd.testing.assert_frame_equal(df, full.iloc[: len(df)].reset_index(drop=True), check_exact=True)

    def test_damaged_record_is_refused(self):
        bad = self.tmp / "bad.oilslog"
        raw = bytearray(self.bin.read_bytes())
        raw[-200] ^= 0xFF  # inside the last frame's compressed records, not the trailer
        bad.write_bytes(bytes(raw))
        with self.assertRaisesRegex(data.LogError, "damaged records"):
            oils_fsw.read_log(bad)

    def test_not_a_log_is_refused(self):
        junk = self.tmp / "junk.oilslog"
        junk.write_bytes(b"OILSLOG1" + bytes(64))
        with self.assertRaisesRegex(data.LogError, "not an OILSLOG8, OILSLOG7 or OILSLOG6 log"):
            oils_fsw.read_log(junk)


@unittest.skipIf(NO_DATA or not OILS, NO_DATA or NEEDS)
class CampaignAsDataFrame(unittest.TestCase):
    def test_small_campaign(self):
        with tempfile.TemporaryDirectory(prefix="oils-data-mc-") as tmp:
            out = Path(tmp) / "mc"
            oils("mc", "run", "--out", out, "--cases", 4, "--seed", 7, "--jobs", 1, "--no-plots", cwd=tmp)
            df = oils_fsw.read_campaign(out)
            summary = df.attrs["summary"]
            self.assertEqual(len(df), 4)
            self.assertEqual(summary["cases"], 4)
            self.assertEqual(list(df["index"]), [0, 1, 2, 3])
            self.assertEqual(df["outcome"].value_counts().to_dict(), summary["outcomes"])
            self.assertEqual(int((df["outcome"] == "landed").sum()), summary["landed"])
            self.assertEqual(df["vertical_speed_mps"].dtype, np.float64)
            header = (out / "cases.csv").read_text().splitlines()[0].split(",")
            self.assertEqual(list(df.columns), header)


EYES = """link = "inproc"
propulsion = "ideal"

[scenario.sensors.camera]
enabled = true
period_ms = 1000.0
width_px = 64
height_px = 48
on_below_altitude_m = 3000.0

[scenario.sensors.lidar]
enabled = true
period_ms = 1000.0
width_px = 32
height_px = 32
on_below_altitude_m = 3000.0
"""


@unittest.skipIf(NO_DATA or not OILS, NO_DATA or NEEDS)
class FramesInMcap(unittest.TestCase):
    def test_frames_decode_as_foxglove_raw_images_with_foxgloves_reader(self):
        # Foxglove's own MCAP reader and its protobuf decoder, with the schema the file
        # carries: one RawImage per announced frame, its pixels the announced bytes
        # (the camera's 12-bit DN shifted to 16 bits), at its time of validity.
        from mcap.reader import make_reader
        from mcap_protobuf.decoder import DecoderFactory

        from oils_fsw.frames import xxh3_64

        with tempfile.TemporaryDirectory(prefix="oils-data-frames-") as tmp:
            tmp = Path(tmp)
            (tmp / "eyes.toml").write_text(EYES)
            log, out = tmp / "eyes.oilslog", tmp / "eyes.mcap"
            oils("run", "--config", tmp / "eyes.toml", "--log", log, cwd=tmp)
            oils("export", log, "--mcap", out, cwd=tmp)
            df = oils_fsw.read_log(log)
            announced = {}
            for k in range(4):
                has = df[f"frame_device[{k}]"] > 0
                for dev, seq, t, h in zip(
                    df[f"frame_device[{k}]"][has], df[f"frame_seq[{k}]"][has],
                    df[f"frame_t_ns[{k}]"][has], df[f"frame_hash[{k}]"][has]
                ):
                    announced[(int(dev), int(seq))] = (int(t), int(h))
            self.assertGreater(len(announced), 100)
            seen = {}
            with open(out, "rb") as f:
                reader = make_reader(f, decoder_factories=[DecoderFactory()])
                topics = ["/camera/image", "/lidar/range"]
                for schema, channel, message, image in reader.iter_decoded_messages(topics=topics):
                    self.assertEqual(schema.name, "foxglove.RawImage")
                    self.assertEqual(schema.encoding, "protobuf")
                    dev = 1 if channel.topic == "/camera/image" else 2
                    channel_seq = message.sequence  # the frame's seq
                    self.assertEqual(image.frame_id, ["camera", "lidar"][dev - 1])
                    if dev == 1:
                        self.assertEqual((image.encoding, image.width, image.height, image.step), ("16UC1", 64, 48, 128))
                        raw = (np.frombuffer(image.data, dtype="<u2") >> 4).astype("<u2").tobytes()
                    else:
                        self.assertEqual((image.encoding, image.width, image.height, image.step), ("32FC1", 32, 32, 128))
                        raw = bytes(image.data)
                    t_ns = image.timestamp.seconds * 1_000_000_000 + image.timestamp.nanos
                    self.assertEqual(message.log_time, t_ns)
                    seen[(dev, channel_seq)] = (t_ns, xxh3_64(raw))
            self.assertEqual(seen, announced)


if __name__ == "__main__":
    unittest.main()
