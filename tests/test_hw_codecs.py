"""Codecs of the iRobot Open Interface and the SICK LMS 2xx telegrams: example frames
worked out from the documented algorithms, round trips, resync after garbage."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hwbridge.create import codec as oi
from hwbridge.create import model as cm
from hwbridge.lms import codec as lms
from hwbridge.lms.model import ScanGeometry

# --- Open Interface ---------------------------------------------------------------


def test_commands_bytes() -> None:
    assert oi.start() == b"\x80"
    assert oi.safe() == b"\x83"
    assert oi.full() == b"\x84"
    assert oi.stop() == b"\xad"  # 173, the Create 2's
    assert oi.baud(57600) == bytes([129, 10])
    assert oi.baud(115200) == bytes([129, 11])
    # drive direct: right 200 mm/s, left -200 mm/s, big-endian signed
    assert oi.drive_direct(200, -200) == bytes([145, 0x00, 0xC8, 0xFF, 0x38])
    assert oi.drive_direct(900, -900) == bytes([145, 0x01, 0xF4, 0xFE, 0x0C])  # +-500
    assert oi.stream([7, 19, 20]) == bytes([148, 3, 7, 19, 20])
    assert oi.pause_resume(False) == bytes([150, 0])
    assert oi.sensors(35) == bytes([142, 35])
    assert oi.query_list([43, 44]) == bytes([149, 2, 43, 44])
    with pytest.raises(oi.CodecError):
        oi.stream([99])


def test_stream_frame_worked_by_hand() -> None:
    # distance -5 mm (0xFFFB) and angle +3 degrees: 19 6 19 FF FB 20 00 03 checksum
    frame = oi.encode_stream_frame((19, 20), {19: -5, 20: 3})
    body = bytes([19, 6, 19, 0xFF, 0xFB, 20, 0x00, 0x03])
    assert frame[:-1] == body
    assert frame[-1] == (256 - sum(body) % 256) % 256 == 0xC3  # 573 = 2 * 256 + 61
    assert sum(frame) % 256 == 0
    assert oi.StreamParser((19, 20)).feed(frame) == [{19: -5, 20: 3}]


FULL_VALUES = {7: 0x03, 19: -120, 20: 45, 21: 2, 22: 16200, 25: 2500, 26: 3000, 32: 0x01,
               33: 1023, 35: 2, 39: -200, 40: 32767, 41: 150, 42: -150, 43: 65535, 44: 1}


def test_every_packet_round_trips() -> None:
    ids = tuple(sorted(oi.PACKETS))
    parser = oi.StreamParser(ids)
    assert parser.feed(oi.encode_stream_frame(ids, FULL_VALUES)) == [FULL_VALUES]


@given(st.lists(st.tuples(st.integers(-32768, 32767), st.integers(-32768, 32767),
                          st.integers(0, 1023), st.integers(0, 3)), min_size=1, max_size=5),
       st.binary(max_size=40))
def test_stream_round_trip_after_garbage(frames: list[tuple[int, int, int, int]],
                                         garbage: bytes) -> None:
    ids = oi.CREATE_STREAM
    want = []
    data = bytearray(garbage.replace(bytes([19]), b""))  # garbage with no false header
    for d, a, analog, mode in frames:
        values = {**FULL_VALUES, 19: d, 20: a, 33: analog, 35: mode}
        want.append({pid: values[pid] for pid in ids})
        data += oi.encode_stream_frame(ids, values)
    parser = oi.StreamParser(ids)
    got = []
    for i in range(0, len(data), 7):  # arrives in pieces
        got += parser.feed(bytes(data[i : i + 7]))
    assert got == want


def test_stream_parser_resyncs_after_bad_checksum_and_truncation() -> None:
    ids = (7, 19, 20)
    good = oi.encode_stream_frame(ids, {7: 0, 19: 10, 20: 1})
    bad = bytearray(good)
    bad[-1] ^= 0x55
    truncated = good[:5]
    parser = oi.StreamParser(ids)
    out = parser.feed(bytes([19, 19, 0, 7]) + bytes(bad) + truncated + good + good)
    assert out == [{7: 0, 19: 10, 20: 1}] * 2
    assert parser.stats.bad_checksum >= 1
    assert parser.stats.errors >= 2


def test_command_parser_device_side() -> None:
    p = oi.CommandParser()
    data = (oi.start() + oi.safe() + b"\x07" + oi.drive_direct(100, -50)
            + oi.stream([7, 19]) + oi.pause_resume(True))
    got = p.feed(data[:6]) + p.feed(data[6:])
    assert [op for op, _ in got] == [128, 131, 145, 148, 150]
    assert oi.parse_drive_direct(got[2][1]) == (100, -50)
    assert oi.parse_id_list(got[3][1]) == (7, 19)
    assert p.unknown == 1


def test_readings_in_si() -> None:
    r = cm.reading_from(FULL_VALUES)
    assert r.bump_left and r.bump_right and not r.wheel_drop
    assert r.voltage_v == pytest.approx(16.2) and r.charge_ah == pytest.approx(2.5)
    assert r.mode == "safe" and r.cargo_analog == 1023
    assert cm.reading_from({7: 0x08}).wheel_drop  # left wheel drop bit 3
    assert cm.IceSensor(500).ice(500) and not cm.IceSensor(500).ice(499)
    assert not cm.IceSensor(500, invert=True).ice(800)
    assert cm.algae_from_digital(0b0001) and not cm.algae_from_digital(0b0010)


def test_packet_odometry_create() -> None:
    odo = cm.Odometry(cm.MODELS["create"])
    odo.update({19: 12, 20: 90})
    odo.update({19: -2, 20: -45})
    d, th = odo.take()
    assert d == pytest.approx(0.010) and th == pytest.approx(math.pi / 4)
    assert odo.take() == (0.0, 0.0)


def test_encoder_odometry_wraps() -> None:
    assert cm.wrap_counts(5, 65530) == 11
    assert cm.wrap_counts(65530, 5) == -11
    odo = cm.Odometry(cm.MODELS["create2"])
    odo.update({43: 65000, 44: 65000})  # reference only
    odo.update({43: (65000 + 1000) % 65536, 44: (65000 + 1000) % 65536})  # both wrap
    d, th = odo.take()
    assert d == pytest.approx(1000 * math.pi * 72.0 / 508.8 / 1000.0)
    assert th == pytest.approx(0.0)
    odo.update({43: 10, 44: 10 + 100})  # right wheel ahead: counter-clockwise
    d, th = odo.take()
    assert th == pytest.approx(100 * cm.MM_PER_COUNT / 1000.0 / 0.235)


def test_wheels_and_watchdog() -> None:
    assert cm.wheels_from_cmd(0.2, 0.0, 0.26) == (200, 200)
    r, left = cm.wheels_from_cmd(0.5, 2.0, 0.26)  # scaled, curvature kept
    assert max(abs(r), abs(left)) == 500 and r > left
    wd = cm.Watchdog(0.5)
    assert wd.expired(0.0)  # never commanded
    wd.feed(1.0)
    assert not wd.expired(1.4)
    assert wd.expired(1.6) and wd.expired(1.7)
    assert wd.trips == 1


# --- SICK LMS 2xx -----------------------------------------------------------------

# Telegrams published with their CRC (LMS 2xx telegram listings); ours must agree.
DOCUMENTED = [
    ("02 00 02 00 20 24", "34 08"),  # continuous output of all values
    ("02 00 02 00 20 25", "35 08"),  # stop continuous output
    ("02 00 02 00 30 01", "31 18"),  # request one scan
    ("02 00 02 00 20 42", "52 08"),  # 9600 baud
    ("02 00 01 00 31", "15 12"),  # status request
    ("02 80 03 00 A0 00 10", "16 0A"),  # reply: mode change accepted, status 0x10
]


@pytest.mark.parametrize("body,crc", DOCUMENTED)
def test_sick_crc_matches_documented_telegrams(body: str, crc: str) -> None:
    b = bytes.fromhex(body)
    assert lms.crc16(b).to_bytes(2, "little") == bytes.fromhex(crc)


def test_sick_crc_first_steps_by_hand() -> None:
    # STX alone: crc 0 -> shift 0 -> xor (0 << 8 | 0x02) = 0x0002
    assert lms.crc16(b"\x02") == 0x0002
    # then 0x00: shift -> 0x0004, xor (0x02 << 8 | 0x00) = 0x0204
    assert lms.crc16(b"\x02\x00") == 0x0204
    # 0x80 0x00 0x00: 0x0080, then 0x0100 ^ 0x8000 = 0x8100, then the top bit shifts
    # out and xors the generator: 0x0200 ^ 0x8005 = 0x8205 (xor 0x0000)
    assert lms.crc16(b"\x80\x00\x00") == 0x8205


def test_host_telegrams() -> None:
    assert lms.mode_change(lms.CONTINUOUS) == bytes.fromhex("020002002024 3408")
    assert lms.set_baud(9600) == bytes.fromhex("020002002042 5208")
    assert lms.request_values() == bytes.fromhex("020002003001 3118")
    v = lms.variant(180, 50)
    assert v[:9] == bytes.fromhex("02 00 05 00 3B B4 00 32 00")
    assert lms.crc16(v[:-2]).to_bytes(2, "little") == v[-2:]
    with pytest.raises(lms.CodecError):
        lms.set_baud(115200)


def test_measured_values_mm_and_cm() -> None:
    geom = ScanGeometry()
    assert geom.beams == 361
    ranges = [1.0 + 0.01 * j for j in range(geom.beams)]
    ranges[5] = math.inf
    mm = lms.LmsConfig(lms.UNIT_MM)
    raw = lms.ranges_to_values(ranges, mm)
    data = lms.encode_values(raw, mm) + b"\x10"
    assert int.from_bytes(data[:2], "little") == 361 | 0x4000
    tel = lms.reply(lms.REQUEST_VALUES, data[:-1])
    assert len(tel) == 732  # the size HARDWARE_NOTES gives for 361 values
    (parsed,) = lms.TelegramParser().feed(tel)
    assert isinstance(parsed, lms.Telegram) and parsed.command == lms.VALUES_REPLY
    got = lms.decode_values(parsed.data, mm)
    assert got.unit == lms.UNIT_MM and got.status == 0x10 and got.real_time_index is None
    out = lms.values_to_ranges(got.values, mm)
    assert out[5] == geom.range_max_m == mm.range_max_m == 8.183
    assert out[0] == pytest.approx(1.0) and out[360] == pytest.approx(4.6)
    cm = lms.LmsConfig(lms.UNIT_CM)
    cm_data = lms.encode_values(lms.ranges_to_values([2.5, 30.0], cm), cm)
    got = lms.decode_values(cm_data + b"\x10", cm)
    assert got.unit == lms.UNIT_CM and got.values == [250, 3000]
    assert lms.values_to_ranges(got.values, cm) == pytest.approx([2.5, 30.0])
    assert cm.range_max_m == 81.83
    # flag bits above the 13 distance bits are masked off
    flagged = (361 | 0x4000).to_bytes(2, "little") + (0x2000 | 1500).to_bytes(2, "little") * 361
    assert lms.decode_values(flagged + b"\x10").values[0] == 1500


def test_configuration_sets_range_bits_units_and_real_time_indices() -> None:
    # the 0xF4 reply: availability at byte 4, measuring mode at 5, units at 6
    data = lms.encode_config(lms.LmsConfig(lms.UNIT_MM, 0x04, lms.REAL_TIME_INDICES))
    assert len(data) == 34 and data[4:7] == bytes([0x02, 0x04, 0x01])
    config = lms.decode_config(data + b"\x10")
    assert config == lms.LmsConfig(lms.UNIT_MM, 0x04, 0x02)
    assert config.range_bits == 14 and config.range_max_m == 16.375
    assert config.real_time_indices
    # 16 m in mm: 12.5 m needs the 14th bit; the real-time indices are two bytes more
    raw = lms.ranges_to_values([12.5, math.inf], config)
    assert raw == [12500, 16375]
    got = lms.decode_values(lms.encode_values(raw, config, 300, telegram_index=7) + b"\x10",
                            config)
    assert got.values == raw and (got.real_time_index, got.telegram_index) == (300 % 256, 7)
    assert lms.values_to_ranges(got.values, config) == [12.5, 16.375]
    # the same bytes read as the default 8 m mode lose the bit, and the indices are too many
    with pytest.raises(lms.CodecError):
        lms.decode_values(lms.encode_values(raw, config, 1) + b"\x10")
    assert lms.LmsConfig(lms.UNIT_MM, 0x06).range_max_m == 32.759
    assert lms.LmsConfig(lms.UNIT_CM, 0x00).range_max_m == 81.83
    for bad in ((lms.UNIT_MM, 0x3F), (0x07, 0x00)):  # reflectivity, unknown units
        with pytest.raises(lms.CodecError):
            lms.LmsConfig(*bad)
    assert lms.request_config() == bytes([0x02, 0x00, 0x01, 0x00, 0x74]) + lms.crc16(
        bytes([0x02, 0x00, 0x01, 0x00, 0x74])).to_bytes(2, "little")


def test_measured_values_status_and_partial_bits() -> None:
    raw = [1000] * 361
    whole = lms.decode_values(lms.encode_values(raw) + b"\x10")
    assert not whole.fatal and whole.partial == 0
    assert lms.decode_values(lms.encode_values(raw) + b"\x14").fatal  # bits 0-2: 4
    assert not lms.decode_values(lms.encode_values(raw) + b"\x13").fatal  # 3, an error
    data = lms.encode_values(raw, partial=0b101)  # flag and index 1 (0.25 degrees)
    assert int.from_bytes(data[:2], "little") == 361 | 0x2800 | 0x4000
    assert lms.decode_values(data + b"\x10").partial == 0b101


def test_telegram_parser_ack_nak_and_resync() -> None:
    good = lms.reply(lms.MODE, b"\x00")
    bad = bytearray(good)
    bad[5] ^= 0xFF
    stream = (bytes([lms.ACK, lms.NAK]) + b"\xff\x02\x80\x06" + bytes(bad) + good[:4]
              + good)
    p = lms.TelegramParser()
    out = []
    for b in stream:
        out += p.feed(bytes([b]))
    tels = [x for x in out if isinstance(x, lms.Telegram)]
    assert tels == [lms.Telegram(0x80, lms.MODE_REPLY, b"\x00\x10")]
    assert lms.ACK in out and lms.NAK in out
    assert p.stats.errors >= 1


@settings(max_examples=30)
@given(st.lists(st.integers(0, 8183), min_size=1, max_size=401), st.binary(max_size=30))
def test_values_round_trip_after_garbage(raw: list[int], garbage: bytes) -> None:
    tel = lms.reply(lms.REQUEST_VALUES, lms.encode_values(raw))
    p = lms.TelegramParser()
    out = [x for x in p.feed(garbage.replace(b"\x02", b"") + tel)
           if isinstance(x, lms.Telegram)]
    assert len(out) == 1
    got = lms.decode_values(out[0].data)
    assert (got.unit, got.values) == (lms.UNIT_MM, raw)


def test_host_side_parser_reads_host_telegrams() -> None:
    p = lms.TelegramParser(expect_reply=False)
    (t,) = p.feed(lms.variant(100, 25))
    assert isinstance(t, lms.Telegram)
    assert t.command == lms.VARIANT and t.data == bytes([100, 0, 25, 0])
    with pytest.raises(ValueError):
        ScanGeometry(180, 25)


def test_scan_message_on_the_wire() -> None:
    from wire import DecodeError, Keys, Scan, decode, encode

    def scan(ranges: list[float], step: float = math.radians(0.5)) -> Scan:
        return Scan(t=1.5, k=7, ranges=ranges, scanner_x=3.0, scanner_y=-2.0,
                    scanner_theta=1.57, angle_min=-math.pi / 2, angle_step=step,
                    range_max=8.183)

    good = scan([1.0, 8.183])
    assert decode(Scan, encode(good)) == good
    assert Keys("btrack/lab").scan() == "btrack/lab/laser/scan"
    for bad in (scan([]), scan([-1.0]), scan([1.0], step=0.0)):
        with pytest.raises(DecodeError):
            decode(Scan, encode(bad))



def test_start_link_resends_until_the_stream_flows() -> None:
    from hwbridge.create import link as ln

    link = ln.StartLink(ln.LinkTiming(retry_s=0.5, tries=3, slow_retry_s=2.0, lost_s=1.0))
    link.restart(0.0)
    sent = [t / 10 for t in range(0, 100) if link.step(t / 10).send_burst]
    # three quick tries, then a slower retry every 2 s (the give-up reported once)
    assert sent[:3] == [0.0, 0.5, 1.0] and sent[3:5] == [3.5, 5.5]
    assert link.state == ln.RETRYING and link.bursts == len(sent)
    link.frame(10.0)
    assert link.state == ln.STREAMING
    assert link.step(10.9) == ln.Step(False)  # frames may be late...
    step = link.step(11.1)  # ...but a stream silent for lost_s has stopped
    assert step == ln.Step(True, (ln.STREAM_LOST,)) and link.state == ln.STARTING
    link.frame(11.2)
    assert link.step(11.3) == ln.Step(False) and link.losses == 1
    link.restart(20.0)  # the port was reopened: a burst at once
    assert link.step(20.0).send_burst


def test_start_link_reports_giving_up_once() -> None:
    from hwbridge.create import link as ln

    link = ln.StartLink(ln.LinkTiming(retry_s=0.5, tries=2))
    link.restart(0.0)
    reports = [r for t in range(0, 100) for r in link.step(t / 10).reports]
    assert reports.count(ln.GAVE_UP) == 1


def test_start_link_warns_while_no_frame_comes_rate_limited() -> None:
    from hwbridge.create import link as ln

    link = ln.StartLink(ln.LinkTiming(warn_after_s=2.0, warn_every_s=10.0))
    link.restart(0.0)
    warned = [t / 10 for t in range(0, 300) if ln.NO_STREAM in link.step(t / 10).reports]
    assert warned == [2.0, 12.0, 22.0] and link.warnings == 3
    link.frame(30.0)
    assert not [t for t in range(31, 60) if link.step(t / 2).reports]  # streaming: quiet
    link.frame(60.0)
    warned = [t / 10 for t in range(600, 700) if ln.NO_STREAM in link.step(t / 10).reports]
    assert warned == [62.0]  # lost at 61.0 s; the warning counts from the last frame


def test_packet_odometry_bounds_the_requested_motion_by_the_packets() -> None:
    po = cm.PacketOdometry(wheel_base_m=0.25, period_s=0.015)
    safe = {7: 0, 35: 2}
    # a slow spin, +-50 mm/s: 0 mm and 0.34 degrees a frame, read as 0 and 0
    turn = {**safe, 19: 0, 20: 0, 41: 50, 42: -50}
    d, th = po.step(turn)
    assert d == 0.0 and th == pytest.approx(100 * 0.015 / 250)  # rad: (vr - vl) t / base
    # stalled against a wall: asked to spin fast, the packets read nothing; believed no
    # further than a degree a frame
    po.reset()
    d, th = po.step({**safe, 19: 0, 20: 0, 41: 500, 42: -500})
    assert th == pytest.approx(math.radians(1.0))
    # the request and the packets agree within a unit: the request's finer figure stands
    po.reset()
    d, th = po.step({**safe, 19: 7, 20: 0, 41: 500, 42: 500})
    assert d == pytest.approx(0.0075)
    # wheels not driven (passive mode, or a wheel dropped): the packets as they are
    po.reset()
    assert po.step({7: 0, 35: 1, 19: 123, 20: 10, 41: 500, 42: -500}) == pytest.approx(
        (0.123, math.radians(10)))
    po.reset()
    assert po.step({**safe, 7: 0x08, 19: 5, 20: 0, 41: 500, 42: 500})[0] == 0.005


def test_a_scan_with_real_time_indices_as_the_telegram_listing_lays_it_out() -> None:
    """Telegram listing 8007954, table 7-25: with "send real-time indices" on (table
    7-122, block C, bit 1) a B0 reply's values are followed by two bytes, the scan counter
    and the telegram counter, then the status. Built here byte by byte, not by our
    encoder (which read one index byte before: every such scan was refused)."""
    config = lms.LmsConfig(lms.UNIT_MM, 0x00, lms.REAL_TIME_INDICES)
    data = bytes([0x03, 0x40,  # 3 values, unit mm (bit 14)
                  0xE8, 0x03, 0xD0, 0x07, 0xF7, 0x1F,  # 1000 mm, 2000 mm, 0x1FF7 (overflow)
                  0x2A, 0x05,  # scan counter 42, telegram counter 5
                  0x10])  # status: no error
    tel = bytes([0x02, 0x80, 12, 0x00, 0xB0]) + data
    tel += lms.crc16(tel).to_bytes(2, "little")
    (parsed,) = lms.TelegramParser().feed(tel)
    assert isinstance(parsed, lms.Telegram)
    got = lms.decode_values(parsed.data, config)
    assert got.values == [1000, 2000, 0x1FF7] and got.status == 0x10
    assert (got.real_time_index, got.telegram_index) == (42, 5)
    assert lms.values_to_ranges(got.values, config) == [1.0, 2.0, 8.183]


@pytest.mark.parametrize("mode", [0x05, 0x06, 0x0F])
def test_the_32_m_modes_codes_are_not_ranges(mode: int) -> None:
    """Telegram listing, table 10-15: in a 32 m mode 0x7FF7 to 0x7FFF are codes (value
    above the maximum, no echo, dazzled, ...), 32.759 m the longest range. Mode 0x0F
    (32 m, no flags) read 16 bits before, so its codes came out as ranges of 32.76 m."""
    config = lms.LmsConfig(lms.UNIT_MM, mode)
    codes = [0x7FF7, 0x7FFA, 0x7FFB, 0x7FFD, 0x7FFE, 0x7FFF]
    data = (len(codes) + 1 | 0x4000).to_bytes(2, "little") + b"".join(
        v.to_bytes(2, "little") for v in [32000, *codes]) + b"\x10"
    got = lms.decode_values(data, config)
    assert config.range_max_m == 32.759
    assert lms.values_to_ranges(got.values, config) == [32.0] + [32.759] * len(codes)
