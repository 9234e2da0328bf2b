"""`make models`: retrain the shipped default models from scratch and install them into the
package (``python/ikid/models/*.safetensors``). ONNX copies and run logs go to ``out/models``.

Budget: the three configs' ``max_minutes`` (6 + 4 + 2) plus simulation and scoring stay under
15 minutes on 2 CPU cores.
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

from ikid_training import CONFIG_DIR as CONFIGS
from ikid_training.train import load_config, run

SHIPPED = ["wrist-ik", "wrist-chain", "wrist-id"]
# Run from a source checkout: the shipped models live in the package sources, not in site-packages.
PACKAGE_MODELS = Path("python/ikid/models")


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path("out/models"))
    parser.add_argument(
        "--install", type=Path, default=PACKAGE_MODELS, help="where the shipped .safetensors go"
    )
    parser.add_argument("--quiet", action="store_true")
    parser.add_argument(
        "names", nargs="*", metavar="NAME", help=f"retrain only these (default: all of {', '.join(SHIPPED)})"
    )
    args = parser.parse_args()
    unknown = sorted(set(args.names) - set(SHIPPED))
    if unknown:
        parser.error(f"unknown model(s) {', '.join(unknown)}; the shipped ones are {', '.join(SHIPPED)}")
    start = time.perf_counter()
    args.install.mkdir(parents=True, exist_ok=True)
    for name in args.names or SHIPPED:
        _, path = run(load_config(CONFIGS / f"{name}.toml"), args.out, progress=not args.quiet)
        shutil.copyfile(path, args.install / path.name)
    print(
        f"make models: {len(args.names or SHIPPED)} models in {(time.perf_counter() - start) / 60:.1f} min "
        f"-> {args.install}"
    )


if __name__ == "__main__":
    main()
