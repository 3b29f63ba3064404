"""DVC stage: the numeric fingerprint (lfdt/box_push_jobs/fingerprint.py): a tiny workload through every numeric
component of the pipeline, hashed. Where the numeric code paths are pinned, every x86-64 CPU with AVX2
writes the same file."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths)

from lfdt import numerics, stage
from lfdt.box_push_jobs import fingerprint


def run() -> None:
    args = stage.parser(__doc__, {"out": "where the fingerprint (JSON) goes"}).parse_args()
    doc = fingerprint.report(fingerprint.compute(log=print))
    stage.write_json(args.out, doc)
    info = numerics.describe()
    print(f"fingerprint of numerics '{info['numerics']}' on {info['cpu_model']} ({info['cpu_isa']}): {args.out}")


if __name__ == "__main__":
    stage.main(run)
