"""Capture from sensor boards: wire protocols (:mod:`triaxcal.io.protocol`, pure) and readers."""

from .protocol import (
    PROTOCOLS,
    RAW_SCALES,
    BinaryDecoder,
    DecoderStats,
    FramedDecoder,
    RawDecoder,
    TextDecoder,
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
    "make_decoder",
]
