"""One module per `ikid` command, each with ``add_parser(sub)`` and ``run(args) -> int``;
:data:`ikid.cli.REGISTRY` lists them in the order `ikid --help` shows them."""
