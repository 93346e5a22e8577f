"""The NARVis network on flows it never trained on and its held-out suite
never scored (clvis.training.flows.PROBE_FLOWS: a von Kármán street, Hill's
spherical vortex, a Kelvin–Helmholtz shear layer), against its baselines:
the suite's cases (256² at 0.25x, 1x and 4x the training density, 512² at
1x; hemisphere and grid views, two frames each) on those flows, so that a
change tuned on the suite can be checked on geometry it never saw.

    python bench/narvis_unseen.py [--quick] [--model-dir DIR] [--json OUT]

--quick: the 256² 1x rows only (6 rows, about a minute here); the full run
is 24 rows. Prints the rows and the table ``clvis eval`` writes into a card.
bench/results/README.md has the output. A measuring script, not a test.
"""

from __future__ import annotations

import argparse
import json

from clvis.training import evaluate as ev
from clvis.training.flows import PROBE_FLOWS


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="the 256x256 1x rows only")
    ap.add_argument("--model-dir", default=None, help="a trained model's folder (default: the shipped)")
    ap.add_argument("--json", default=None, metavar="OUT", help="also write the result here")
    args = ap.parse_args()
    cases = [
        ev.Case(f, size, d, sampler, frames=2)
        for f in PROBE_FLOWS
        for sampler in ("hemisphere", "grid")
        for size, ds in (((256, 256), (0.25, 1.0, 4.0)), ((512, 512), (1.0,)))
        for d in ds
        if not args.quick or (size == (256, 256) and d == 1.0)
    ]
    result = ev.evaluate("narvis", model_dir=args.model_dir, cases=cases)
    print(ev.table(result))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
