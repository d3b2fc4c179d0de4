"""``embodied-adhoc pomdp export DOMAIN --out DIR``: write a chapter-5 library as Cassandra ``.pomdp`` files.

One file per model (``DOMAIN-mK.pomdp``) plus ``library.json`` (task names, sizes, Table 5.2's horizon and noise,
the build options), so that SARSOP and pomdp-solve users can load the models. The writer is
:func:`embodied_adhoc.decision.pomdp_io.write_pomdp` (reading a file back gives the same model). The power plant's
models are written at their own sizes (105 and 97 states).
"""

from __future__ import annotations

import argparse
import json


def register_export(commands) -> None:
    """Add the ``export`` subcommand to the ``pomdp`` command group."""
    from embodied_adhoc.commands.arguments import output_folder
    from embodied_adhoc.domains.chapter5 import CHAPTER5_DOMAINS
    from embodied_adhoc.experiments.domains.chapter5_options import add_library_arguments

    export = commands.add_parser(
        "export",
        help="write a chapter-5 model library (one .pomdp per task x teammate) for SARSOP / pomdp-solve",
        description="Build a chapter-5 library from its rules and write each model as a Cassandra .pomdp file, "
        "plus library.json describing them.",
    )
    export.add_argument(
        "domain", choices=CHAPTER5_DOMAINS, metavar="DOMAIN", help=", ".join(CHAPTER5_DOMAINS)
    )
    export.add_argument(
        "--out",
        type=output_folder,
        required=True,
        metavar="DIR",
        help="output folder (created; checked first)",
    )
    export.add_argument("--json", action="store_true", help="print one JSON object")
    add_library_arguments(export)
    export.set_defaults(func=_export)


def _export(args: argparse.Namespace) -> int:
    import time

    from embodied_adhoc.atomic import atomic_write_text
    from embodied_adhoc.decision.pomdp_io import write_pomdp
    from embodied_adhoc.domains.chapter5 import build_library
    from embodied_adhoc.experiments.domains.chapter5_options import library_options

    options = library_options(args.domain, args)
    start = time.perf_counter()
    library = build_library(args.domain, **options)
    built = time.perf_counter() - start
    models = library.native_pomdps or library.pomdps
    args.out.mkdir(parents=True, exist_ok=True)
    files = []
    for k, pomdp in enumerate(models):
        path = write_pomdp(pomdp, args.out / f"{args.domain}-m{k}.pomdp")
        files.append(
            {
                "file": path.name,
                "task": library.task_names[k],
                "states": pomdp.n_states,
                "actions": pomdp.n_actions,
                "observations": pomdp.n_observations,
            }
        )
    document = {
        "domain": args.domain,
        "options": options,
        "horizon": library.horizon,
        "noise": library.noise,
        "perseus_beliefs": library.n_beliefs,
        "discount": models[0].discount,
        "models": files,
        "build_seconds": built,
        "write_seconds": time.perf_counter() - start - built,
    }
    atomic_write_text(args.out / "library.json", json.dumps(document, indent=2) + "\n")
    if args.json:
        print(json.dumps(document))
    else:
        print(
            f"{args.domain}: {len(files)} model(s) written to {args.out}/ in {time.perf_counter() - start:.2f} s"
        )
        for entry in files:
            print(f"  {entry['file']}: {entry['task']} ({entry['states']} states)")
    return 0
