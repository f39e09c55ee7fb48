"""Hostile CARMEN logs: corrupt or truncated compression, bad PARAM values,
too few beams and negative ranges are a ``LogFormatError`` naming the file and the line."""

from __future__ import annotations

import bz2
import gzip
from pathlib import Path

import pytest

from estimators.datasets.carmen import CarmenFormatError, load_log
from lidar_env.core.errors import LogFormatError

FLASER = "FLASER 4 1.0 2.0 3.0 4.5 0.1 0.2 0.3 1.1 1.2 1.3 100.5 host 0.5"
LOG = "PARAM robot_frontlaser_offset 0.2 nohost 0\n" + "\n".join([FLASER] * 400) + "\n"


def write(tmp_path: Path, data: bytes) -> Path:
    path = tmp_path / "log.clf"
    path.write_bytes(data)
    return path


@pytest.mark.parametrize("compress", [gzip.compress, bz2.compress])
@pytest.mark.parametrize("damage", ["truncate", "flip"])
def test_corrupt_or_truncated_compression_names_the_file(tmp_path, compress, damage):
    data = bytearray(compress(LOG.encode("ascii")))
    if damage == "truncate":
        data = data[: len(data) // 2]
    else:
        for k in range(20, len(data) - 20, 7):
            data[k] ^= 0x5A
    path = write(tmp_path, bytes(data))
    with pytest.raises(CarmenFormatError, match="corrupt or truncated compressed data") as caught:
        load_log(path)
    assert caught.value.source == str(path)
    assert str(path) in str(caught.value)


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        ("PARAM robot_frontlaser_offset abc", "PARAM robot_frontlaser_offset: expected numbers"),
        ("PARAM robot_frontlaser_offset inf", "PARAM robot_frontlaser_offset: expected finite"),
        ("PARAM robot_frontlaser_offset nan", "PARAM robot_frontlaser_offset: expected finite"),
        ("FLASER 0 0.1 0.2 0.3 1.1 1.2 1.3 100.5 host 0.5", "expected at least 2 beams, got 0"),
        ("FLASER 1 1.0 0.1 0.2 0.3 1.1 1.2 1.3 100.5 host 0.5", "at least 2 beams, got 1"),
        (FLASER.replace(" 2.0 ", " -2.0 ", 1), r"expected ranges >= 0 \[m\], got -2.0 at beam 1"),
        (FLASER.replace(" 2.0 ", " nan ", 1), "FLASER ranges: expected finite numbers"),
    ],
)
def test_bad_fields_are_named_with_file_and_line(tmp_path, line, reason):
    path = write(tmp_path, f"# header\n{FLASER}\n{line}\n{FLASER}\n".encode("ascii"))
    with pytest.raises(LogFormatError, match=reason) as caught:
        load_log(path)
    assert caught.value.line_number == 3
    assert f"{path}, line 3" in str(caught.value)


def test_a_good_log_still_reads_in_every_compression(tmp_path):
    for compress in (lambda b: b, gzip.compress, bz2.compress):
        log = load_log(write(tmp_path, compress(LOG.encode("ascii"))))
        assert len(log.scans) == 400
        assert log.scans[0].laser_offset[0] == 0.2
