"""`robotadapt explore`: a local web app where every change of a law, a gain or a setting re-runs the loop
(docs/explorer.md; the extra [explore], Bokeh)."""

from __future__ import annotations

import argparse

from ..validation import ConfigError, require_extra


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("explore", help="a local web app: move a gain, see the run (extra [explore])",
                       description="Serve the explorer on this machine: the scenario's laws, a slider per gain, the "
                       "run's figures and metrics redrawn on every change, the view in the page's URL. Only requests "
                       "addressed to this server are answered; Ctrl-C stops it.")
    p.add_argument("scenario", nargs="?", default="example-6.3.1",
                   help="a packaged scenario (see `robotadapt list`) or a TOML file, the only file the page runs "
                        "(default example-6.3.1)")
    p.add_argument("--port", type=int, default=5006, help="the port to listen on (default 5006; 0: a free one)")
    p.add_argument("--host", default="127.0.0.1",
                   help="the address to listen on (default 127.0.0.1, this machine only; 0.0.0.0 opens it to the "
                        "network, with --allow-origin naming how others reach it)")
    p.add_argument("--allow-origin", action="append", default=[], metavar="HOST:PORT",
                   help="another name the page may be reached by (repeatable), e.g. lecture-pc.local:5006")
    p.add_argument("--no-browser", action="store_true", help="print the URL, open no browser")


def main(args: argparse.Namespace) -> int:
    require_extra("bokeh", "explore", "explore", "the explorer's web server")
    from ..explorer.server import serve
    from ..studies.scenarios import load

    if not 0 <= args.port < 65536:
        raise ConfigError("--port", f"expected 0 … 65535, got {args.port}")
    load(args.scenario)  # a bad scenario is one line and exit 2 before the server starts
    serve(args.scenario, args.host, args.port, args.allow_origin, browser=not args.no_browser,
          announce=lambda line: print(line, flush=True))
    return 0
