"""Capture from sensor boards: the wire protocols (:mod:`triaxcal.io.protocol`, pure: bytes
in, records out) and the serial reader built on them."""

from .protocol import (
    PROTOCOLS,
    RAW_SCALES,
    BinaryDecoder,
    DecoderStats,
    FramedDecoder,
    RawDecoder,
    TextDecoder,
    encode_binary,
    encode_framed,
    encode_raw,
    encode_text,
    make_decoder,
)

__all__ = [
    "PROTOCOLS",
    "RAW_SCALES",
    "BinaryDecoder",
    "DecoderStats",
    "FramedDecoder",
    "RawDecoder",
    "TextDecoder",
    "encode_binary",
    "encode_framed",
    "encode_raw",
    "encode_text",
    "make_decoder",
]
