"""``raf server``: a standalone factory-state server for one round, or a client that asks one.

Without a simulator nothing moves: the parts stay in the incoming warehouse and the machines do not run.
That is what a team needs to test its robot's protocol code against the real SimTwo (point the robot at
this server's address). With ``--query REQ`` it sends requests to a running server and prints the replies.
"""
from __future__ import annotations

import argparse

from ..simtwo.ports import SERVER_UDP_PORT

NAME = "server"
HELP = f"run a standalone factory-state server (UDP {SERVER_UDP_PORT}) for a round, or --query a running one"
ORDER = 40
DESCRIPTION = """\
Run the competition's factory-state server (UDP, plain ASCII: IWP OWP MAP MBP CTL PING) for one round with
a static part layout (no simulator: machines do not run). Requests get STOP until the run starts, which
happens --start-after seconds after launch (0: at once), or when Enter is pressed with --wait-enter.

  raf server --round 3 --seed 4                 serve round 3's seeded layout, started at once
  raf server --parts RGBX --start-after 10      start the run 10 s after launch
  raf server --query IWP --query CTL            ask a running server (raf server or raf sim)

docs/competition.md describes the protocol and the rules as implemented."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..simtwo.ports import LOCALHOST, SERVER_UDP_PORT

    parser.add_argument("--host", default=LOCALHOST,
                        help=f"address to bind, or to query with --query (default {LOCALHOST}; 0.0.0.0 serves "
                             "every interface)")
    parser.add_argument("--port", type=int, default=SERVER_UDP_PORT, help=f"UDP port (default {SERVER_UDP_PORT})")
    parser.add_argument("--round", type=int, default=1, choices=(1, 2, 3), help="round 1, 2 or 3 (default 1)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the organiser's part draw (default 0)")
    parser.add_argument("--parts", metavar="RGBX", help="incoming parts, slot 1 first (R, G, B, X = empty); "
                                                        "overrides the seeded draw")
    parser.add_argument("--duration", type=float, default=600.0, help="round length in seconds (default 600)")
    parser.add_argument("--start-after", type=float, default=0.0, metavar="SECONDS",
                        help="start the run this many seconds after launch (default 0: at once)")
    parser.add_argument("--wait-enter", action="store_true",
                        help="start the run when Enter is pressed on the terminal (the organiser's signal)")
    parser.add_argument("--exit-at-end", action="store_true", help="exit when the round's time is over")
    parser.add_argument("--verbose", action="store_true", help="print every request and its reply")
    parser.add_argument("--query", action="append", metavar="REQ",
                        help="client mode: send REQ (e.g. IWP, CTL, PING) to --host:--port and print the reply; "
                             "may be repeated")
    parser.add_argument("--timeout", type=float, default=1.0, help="client mode: seconds to wait for a reply")


def run(args) -> int:
    if args.query:
        return _query(args)
    return _serve(args)


def _query(args) -> int:
    import sys

    from ..competition import query

    for req in args.query:
        try:
            reply = query(req, args.host, args.port, timeout=args.timeout)
        except TimeoutError as e:
            print(f"raf server: error: {e}", file=sys.stderr)
            return 1
        print(f"{req} -> {reply}" if len(args.query) > 1 else reply)
    return 0


def _serve(args) -> int:
    import logging
    import math
    import signal
    import sys
    import threading
    import time

    from ..competition import Factory, FactoryServer, RoundSetup, ctl_reply
    from ..errors import ConfigError
    from ..field import load_field

    if not math.isfinite(args.start_after) or args.start_after < 0:
        raise ConfigError(f"--start-after must be a number of seconds >= 0, got {args.start_after}")
    setup = RoundSetup.make(args.round, args.seed, args.parts, duration=args.duration)
    factory = Factory(load_field(args.field), setup)
    t0 = time.monotonic()

    def clock() -> float:
        return time.monotonic() - t0

    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(asctime)s %(message)s", stream=sys.stdout)
    server = FactoryServer(factory, args.host, args.port, clock, log_requests=args.verbose).start()
    host, port = server.address
    print(f"factory-state server on udp {host}:{port} (field {factory.field.name})")
    print(f"  {setup.describe()}")
    print(f"  static layout: IWP {factory.letters('incoming')}  OWP {factory.letters('outgoing')}  "
          f"MAP {factory.letters('machine_A')}  MBP {factory.letters('machine_B')}  (machines do not run)")
    if args.wait_enter:
        print("  requests get STOP until you press Enter", flush=True)
    elif args.start_after > 0:
        print(f"  requests get STOP until the run starts in {args.start_after:g} s", flush=True)

    done = threading.Event()
    enter = threading.Event()
    old = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            old[sig] = signal.signal(sig, lambda *_: done.set())
    if args.wait_enter:
        def wait_for_enter():
            try:
                sys.stdin.readline()
            finally:
                enter.set()

        threading.Thread(target=wait_for_enter, name="wait-enter", daemon=True).start()
    announced_end = False
    try:
        while not done.is_set():
            now = clock()
            if not factory.started and ((args.wait_enter and enter.is_set())
                                        or (not args.wait_enter and now >= args.start_after)):
                factory.start(now)
                print(f"run started at {now:.2f} s: CTL {ctl_reply(factory.time_left(now))} and counting",
                      flush=True)
            if factory.over(now) and not announced_end:
                announced_end = True
                print(f"round over at {now:.2f} s (CTL T000); still answering", flush=True)
                if args.exit_at_end:
                    break
            done.wait(0.05)
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        server.stop()
        c = server.counters
        print(f"server stopped: {c['requests']} requests, {c['replies']} replies, {c['stop_replies']} STOP, "
              f"{c['errors']} errors ({', '.join(f'{k} {c[k]}' for k in ('IWP', 'OWP', 'MAP', 'MBP', 'CTL', 'PING'))})")
    return 0
