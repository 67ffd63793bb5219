"""What the clients' programs share: latency quantiles for their JSON
summary, the summary printed and written, and the exit on the
interface's errors."""

import json
import sys
from typing import Callable, Optional, Sequence


def quantiles(values: Sequence[int], unit_ns: float = 1e3, points=(0.5, 0.99), mean: bool = False) -> dict:
    """The count, the quantiles ``points`` (``p50``, ``p99``, ...), the max
    and, where asked, the mean of ``values`` (ns), in units of ``unit_ns``
    (1e3: µs)."""
    if not values:
        return {"count": 0}
    v = sorted(values)
    out = {"count": len(v)}
    for p in points:
        out[f"p{round(p * 100)}"] = v[min(len(v) - 1, int(len(v) * p))] / unit_ns
    out["max"] = v[-1] / unit_ns
    if mean:
        out["mean"] = sum(v) / len(v) / unit_ns
    return out


def emit(summary: dict, out: Optional[str]) -> None:
    """Prints ``summary`` as JSON, and writes it to ``out`` when given."""
    text = json.dumps(summary, indent=2)
    print(text)
    if out:
        with open(out, "w") as f:
            f.write(text + "\n")


def run_main(name: str, main: Callable[[], int], errors: tuple) -> None:
    """Exits with ``main()``'s status; on one of ``errors``, says it as
    ``name: …`` on stderr and exits with 2."""
    try:
        sys.exit(main())
    except errors as e:
        print(f"{name}: {e}", file=sys.stderr)
        sys.exit(2)
