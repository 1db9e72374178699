"""Writes a candump -L log of N frames of every message of a DBC, in turn, with random in-range
signal values encoded by cantools' own encoder (the decode benchmark's input).

Usage: cantools_frames.py DBC N OUT [SEED]
"""

import random
import sys

import cantools


def main():
    dbc, n, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    rng = random.Random(int(sys.argv[4]) if len(sys.argv) > 4 else 1)
    db = cantools.database.load_file(dbc)
    messages = db.messages

    def value(sig):
        if sig.choices:
            return rng.choice(list(sig.choices.keys()))
        lo = sig.minimum if sig.minimum is not None else sig.offset
        hi = sig.maximum if sig.maximum is not None else sig.offset + sig.scale * ((1 << sig.length) - 1)
        raw_lo = int(round((lo - sig.offset) / sig.scale))
        raw_hi = int(round((hi - sig.offset) / sig.scale))
        return sig.offset + sig.scale * rng.randint(min(raw_lo, raw_hi), max(raw_lo, raw_hi))

    t = 1_700_000_000.0
    with open(out, "w") as f:
        for i in range(n):
            m = messages[i % len(messages)]
            data = m.encode({s.name: value(s) for s in m.signals}, scaling=True, strict=True)
            t += 0.000855
            f.write(f"({t:.6f}) vcan0 {m.frame_id:08X}#{data.hex().upper()}\n")


if __name__ == "__main__":
    main()
