#!/usr/bin/env python3
"""Writes the binary seed inputs of fuzz/corpus/ (the text seeds are hand-written files).

Run from anywhere: python3 fuzz/make_seeds.py. Deterministic; rerunning rewrites the same
files. Formats: core/pc2.h, capture/frame_file.h, Modbus TCP (Modbus Messaging on TCP/IP
Implementation Guide v1.0b: MBAP header = transaction id, protocol 0, length, unit id).
"""
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))


def put(target, name, data):
    folder = os.path.join(HERE, "corpus", target)
    os.makedirs(folder, exist_ok=True)
    with open(os.path.join(folder, name), "wb") as f:
        f.write(data)


def pc2(points, frames, start=0.0, sampling=1.0, version=1, magic=b"POINTCACHE2\0", values=None):
    header = magic + struct.pack("<iiffi", version, points, start, sampling, frames)
    if values is None:
        values = [float(i % 7) for i in range(points * frames * 3)]
    return header + struct.pack("<%df" % len(values), *values)


put("pc2", "valid_3v_2f.pc2", pc2(3, 2))
put("pc2", "valid_empty.pc2", pc2(1, 0))
put("pc2", "truncated.pc2", pc2(3, 2)[:-5])
put("pc2", "nan.pc2", pc2(2, 1, values=[0.0, float("nan"), 1.0, 2.0, 3.0, 4.0]))
put("pc2", "negative_count.pc2", pc2(-1, 2, values=[]))
put("pc2", "bad_version.pc2", pc2(1, 1, version=2))
put("pc2", "huge_count.pc2", pc2(0x7FFFFFFF, 0x7FFFFFFF, values=[]))


def fnv1a64(data):
    h = 1469598103934665603
    for b in data:
        h ^= b
        h = (h * 1099511628211) & 0xFFFFFFFFFFFFFFFF
    return h


def frame_record(trigger, width, height, fmt=1, camera=0, payload=None):
    bpp = {1: 1, 2: 2, 3: 3}.get(fmt, 1)
    if payload is None:
        payload = bytes((i * 7) & 0xFF for i in range(width * height * bpp))
    head = b"FDFR" + struct.pack("<IqqiIIIQII", 64, trigger, trigger * 7812500, 2000, width,
                                 height, fmt, len(payload), camera, 0)
    return head + struct.pack("<Q", fnv1a64(head)) + payload


# frame_file: first byte odd = the harness fixes checksums, even = file as is.
two = frame_record(0, 4, 2) + frame_record(1, 4, 2)
put("frame_file", "valid_two.bin", b"\x00" + two)
put("frame_file", "valid_two_fix.bin", b"\x01" + two)
put("frame_file", "torn_tail.bin", b"\x00" + two[:-3])
put("frame_file", "mono16_rgb.bin", b"\x00" + frame_record(0, 2, 2, fmt=2) + frame_record(1, 2, 1, fmt=3))
put("frame_file", "bad_trigger.bin", b"\x00" + frame_record(-5, 2, 2) + frame_record(2, 2, 2))
bad = bytearray(two)
bad[30] ^= 0xFF
put("frame_file", "bad_checksum.bin", b"\x00" + bytes(bad))
put("frame_file", "huge_side_fix.bin", b"\x01" + frame_record(0, 0xFFFFFFFF, 0xFFFFFFFF, payload=b"x"))


# modbus_reply: first byte = profile (0 sim, 1 delta, 2 siemens, 3 invertek), then the reply
# stream for the reads ReadStatus makes (transaction ids 1, 2, 3; unit id 0xFF, libmodbus's TCP
# default, or the profile's unit id).
def read_reply(tid, words, unit=1):
    pdu = bytes([3, 2 * len(words)]) + b"".join(struct.pack(">H", w) for w in words)
    return struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu


def exception_reply(tid, code, unit=1):
    pdu = bytes([0x83, code])
    return struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu


for profile in range(4):
    put("modbus_reply", "running_%d.bin" % profile,
        bytes([profile]) + read_reply(1, [0x0001]) + read_reply(2, [850]) + read_reply(3, [0]))
    put("modbus_reply", "faulted_%d.bin" % profile,
        bytes([profile]) + read_reply(1, [0xFFFF]) + read_reply(2, [0xFFFF]) + read_reply(3, [0xFFFF]))
put("modbus_reply", "busy.bin", b"\x00" + exception_reply(1, 6))
put("modbus_reply", "illegal_address.bin", b"\x01" + exception_reply(1, 2))
put("modbus_reply", "wrong_tid.bin", b"\x00" + read_reply(7, [1]))
put("modbus_reply", "short.bin", b"\x00" + read_reply(1, [1])[:5])
put("modbus_reply", "two_words.bin", b"\x00" + read_reply(1, [1, 2]))


# drive_request: first byte = profile, then records of [length][PDU].
def rec(pdu):
    return bytes([len(pdu)]) + pdu


def fc06(address, value):
    return struct.pack(">BHH", 6, address, value)


def fc16(address, values, count=None, byte_count=None):
    count = len(values) if count is None else count
    byte_count = 2 * count if byte_count is None else byte_count
    return struct.pack(">BHHB", 16, address, count, byte_count) + b"".join(
        struct.pack(">H", v) for v in values)


def fc03(address, count):
    return struct.pack(">BHH", 3, address, count)


# Profile 0 is config/drives/sim.yaml; the fuzzer explores the register map from these.
put("drive_request", "run_set_stop.bin", b"\x00" + rec(fc06(1, 850)) + rec(fc06(0, 1)) +
    rec(fc03(0, 4)) * 3 + rec(fc06(0, 0)))
put("drive_request", "fc16_block.bin", b"\x00" + rec(fc16(0, [1, 900, 0, 0, 0, 10])))
put("drive_request", "fc16_bad_count.bin", b"\x00" + rec(fc16(0, [1, 2], count=200, byte_count=4)))
put("drive_request", "fc16_short.bin", b"\x00" + rec(fc16(0, [1, 2, 3])[:-3]))
put("drive_request", "out_of_range.bin", b"\x00" + rec(fc06(0xFFFF, 1)) + rec(fc16(0xFFF0, [1] * 20)))
for profile in range(1, 4):
    put("drive_request", "profile_%d.bin" % profile,
        bytes([profile]) + b"".join(rec(fc06(a, v)) for a in range(0, 12) for v in (0, 1, 0xFFFF)))


# sweep_resume: rig_log.jsonl records for config/sweeps/demo.yaml (3 instances), whose
# sweep_start carries the script's FNV-1a 64 hash (rig/sweep.cc) so the reader gets past it.
with open(os.path.join(HERE, "..", "config", "sweeps", "demo.yaml"), "rb") as f:
    DEMO_HASH = "%016x" % fnv1a64(f.read())
START = '{"event":"sweep_start","t_ns":1,"script":"demo.yaml","script_hash":"%s"}\n' % DEMO_HASH
put("sweep_resume", "resumable.jsonl", (START +
    '{"event":"step_start","t_ns":2,"instance":0,"hz":6.5}\n'
    '{"event":"step_done","t_ns":3,"instance":0,"hz":6.5,"prompt":"neutral",'
    '"hold":{"seconds":1.0,"samples":100,"target_hz":6.5,"mean_measured_hz":6.49},'
    '"vibrating_s":3.2,"dose_m2_s3":0.8,"exposure":{"peak_rms_m_s2":1.1}}\n'
    '{"event":"step_start","t_ns":4,"instance":1,"hz":8.5}\n').encode())
put("sweep_resume", "finished.jsonl", (START + "".join(
    '{"event":"step_done","t_ns":%d,"instance":%d}\n' % (i + 2, i) for i in range(3)) +
    '{"event":"sweep_done","t_ns":9}\n').encode())
put("sweep_resume", "bad_values.jsonl", (START +
    '{"event":"step_done","instance":7}\n{"event":"x","vibrating_s":-1,"dose_m2_s3":1e308}\n'
    '{"event":"step_done","instance":0,"hold":{"seconds":"1"}}\n').encode())
put("sweep_resume", "other_script.jsonl",
    b'{"event":"sweep_start","script_hash":"0123456789abcdef"}\n{"event":"step_done"}\n')


# mdd (export/mdd.h): big-endian frame count, point count, F float times, then F*V*3 floats.
def mdd(frames, points, times=None, values=None):
    if times is None:
        times = [k / 128.0 for k in range(frames)]
    if values is None:
        values = [float(i % 5) for i in range(frames * points * 3)]
    return struct.pack(">ii", frames, points) + struct.pack(">%df" % len(times), *times) + \
        struct.pack(">%df" % len(values), *values)


put("mdd", "valid_3v_2f.mdd", mdd(2, 3))
put("mdd", "valid_empty.mdd", mdd(0, 4))
put("mdd", "truncated.mdd", mdd(2, 3)[:-3])
put("mdd", "times_backwards.mdd", mdd(2, 1, times=[1.0, 0.5]))
put("mdd", "nan.mdd", mdd(1, 1, values=[0.0, float("nan"), 1.0]))
put("mdd", "huge_counts.mdd", struct.pack(">ii", 0x7FFFFFFF, 0x7FFFFFFF))
put("mdd", "little_endian.mdd", struct.pack("<ii", 2, 3) + mdd(2, 3)[8:])


# detail/masquerade.h: "FDDETAIL", uint32 format version, then the model. A valid model is
# ~700 KB even for a small face, too large for the corpus; these seeds reach the header checks
# and the first length fields, and libFuzzer grows from them.
put("detail_model", "magic_only.bin", b"FDDETAIL")
put("detail_model", "version_1_truncated.bin", b"FDDETAIL" + struct.pack("<I", 1))
put("detail_model", "version_1_huge_length.bin",
    b"FDDETAIL" + struct.pack("<I", 1) + struct.pack("<Q", 1 << 62) + b"subject")
put("detail_model", "version_2_truncated.bin",
    b"FDDETAIL" + struct.pack("<I", 2) + struct.pack("<I", 5) + b"patch")
put("detail_model", "future_version.bin", b"FDDETAIL" + struct.pack("<I", 99) + b"\0" * 64)
put("detail_model", "bad_magic.bin", b"FDDETAIX" + struct.pack("<I", 1))


# dynamics/modal_synthesis.h: "FDMODAL\0", uint32 format version, rig name, fps, resonator
# frequencies, damping, validation residual, 6 input scales, sample count and hash, W (rows =
# 6 (2K + 1) + 1, columns 3S, column-major), propagation flag [method, vertex count, V x S
# floats], "END.". A real model is ~1 MB; a valid one with one resonator and one sample is small.
def modal(resonators=(8.0,), samples=1, propagation_vertices=0, version=1, rows=None,
          fps=128.0, trailer=b"END."):
    def doubles(values):
        return struct.pack("<q", len(values)) + struct.pack("<%dd" % len(values), *values)
    name = b"procedural"
    k = len(resonators)
    rows = 6 * (2 * k + 1) + 1 if rows is None else rows
    out = b"FDMODAL\0" + struct.pack("<I", version) + struct.pack("<I", len(name)) + name
    out += struct.pack("<d", fps) + doubles(list(resonators)) + struct.pack("<dd", 0.3, 0.4)
    out += doubles([1.0] * 6) + struct.pack("<qQ", samples, 12345) + struct.pack("<q", rows)
    out += doubles([0.01 * (i % 5) for i in range(rows * 3 * samples)])
    if propagation_vertices:
        method = b"learned"
        n = propagation_vertices * samples
        out += struct.pack("<B", 1) + struct.pack("<I", len(method)) + method
        out += struct.pack("<q", propagation_vertices)
        out += struct.pack("<q", n) + struct.pack("<%df" % n, *([0.5] * n))
    else:
        out += struct.pack("<B", 0)
    return out + trailer


put("modal_model", "valid_1_resonator_1_sample.bin", modal())
put("modal_model", "valid_with_propagation.bin", modal(resonators=(4.0, 9.0), samples=2,
                                                         propagation_vertices=3))
put("modal_model", "truncated.bin", modal()[:-20])
put("modal_model", "rows_mismatch.bin", modal(rows=7))
put("modal_model", "resonator_above_nyquist.bin", modal(resonators=(70.0,)))
put("modal_model", "future_version.bin", modal(version=9))
put("modal_model", "no_trailer.bin", modal(trailer=b"END!"))
put("modal_model", "magic_only.bin", b"FDMODAL\0")
put("modal_model", "huge_length.bin", b"FDMODAL\0" + struct.pack("<I", 1) + struct.pack("<I", 0xFFFFFFF0))
