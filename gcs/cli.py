"""`gcs`: the ground-station command line.

    gcs run SCENARIO.toml [--in-process | --realtime] [--controller pid|pd]
            [--ideal-actuators] [--duration S] --out DIR
    gcs table1 [--in-process] [--ideal-actuators] [--duration S] --out DIR
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from common.config import ConfigError, load_scenario

DEFAULT_SCENARIOS = Path(__file__).resolve().parent.parent / "config" / "scenarios"


def _positive(text: str) -> float:
    value = float(text)
    if not value > 0.0:
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="gcs", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)

    run = sub.add_parser("run", help="fly a scenario and write DIR/metrics.json")
    run.add_argument("scenario", type=Path)
    mode = run.add_mutually_exclusive_group()
    mode.add_argument("--in-process", action="store_true",
                      help="compose the FCU core and the plant in this process")
    mode.add_argument("--realtime", action="store_true",
                      help="sitl and fcu paced by the wall clock instead of lockstep")
    run.add_argument("--controller", choices=("pid", "pd"),
                     help="override the scenario's controller")
    run.add_argument("--ideal-actuators", action="store_true",
                     help="rotors and tilt servos follow their commands instantly")
    run.add_argument("--duration", type=_positive, metavar="S",
                     help="cut the scenario short after S simulated seconds")
    run.add_argument("--sim-link", choices=("udp", "tcp"), default="udp",
                     help="transport of the simulator link (default udp)")
    run.add_argument("--out", type=Path, required=True, metavar="DIR")

    t1 = sub.add_parser("table1", help="Case I and Case II, PID and PD, beside the paper")
    t1.add_argument("--in-process", action="store_true",
                    help="run in this machine's processes without MAVLink")
    t1.add_argument("--ideal-actuators", action="store_true")
    t1.add_argument("--duration", type=_positive, metavar="S")
    t1.add_argument("--scenarios", type=Path, default=DEFAULT_SCENARIOS, metavar="DIR",
                    help="folder holding the four scenario files")
    t1.add_argument("--jobs", type=int, default=None, help="parallel processes")
    t1.add_argument("--out", type=Path, required=True, metavar="DIR")
    return parser


def _summary(m: dict) -> str:
    pos, att = m["position_error_m"], m["attitude_error_rad"]
    return (f"{m['scenario']} [{m['controller']}] {m['status']}: "
            f"{m['sim_time_s']:.1f} s simulated in {m['wall_time_s']:.1f} s "
            f"({m['real_time_factor']:.1f}x real time)\n"
            f"  position error  max {pos['max']:.6f} m   mean {pos['mean']:.6f} m   "
            f"rmse {pos['rmse']:.6f} m\n"
            f"  attitude error  max {att['max']:.3e} rad   mean {att['mean']:.3e} rad   "
            f"rmse {att['rmse']:.3e} rad\n"
            f"  fcu step        p50 {m['fcu_step_us']['p50']:.1f} us   "
            f"p99 {m['fcu_step_us']['p99']:.1f} us   transport {m['transport']}, "
            f"lockstep {str(m['lockstep']).lower()}, mission completed "
            f"{str(m['mission_completed']).lower()}")


def cmd_run(args: argparse.Namespace) -> int:
    from gcs.inprocess import apply_overrides, run_scenario
    from gcs.process_run import RunError, run_processes
    from gcs.runio import write_run

    scenario = apply_overrides(load_scenario(args.scenario), controller=args.controller,
                               ideal_actuators=True if args.ideal_actuators else None,
                               duration_s=args.duration)
    if args.in_process:
        result = run_scenario(scenario)
        write_run(args.out, scenario, result)
        metrics = result.metrics
    else:
        try:
            metrics = run_processes(scenario, args.out, realtime=args.realtime,
                                    transport=args.sim_link)
        except RunError as exc:
            print(f"gcs run: {exc}", file=sys.stderr)
            return 1
    print(_summary(metrics))
    print(f"  wrote {args.out / 'metrics.json'}")
    return 0 if metrics["status"] == "completed" else 1


def cmd_table1(args: argparse.Namespace) -> int:
    from gcs.table1 import run_table1

    table = run_table1(args.scenarios, args.out, ideal=args.ideal_actuators,
                       duration_s=args.duration, workers=args.jobs,
                       in_process=args.in_process)
    print((args.out / "table1.md").read_text())
    print(f"wrote {args.out / 'table1.md'} and {args.out / 'table1.json'}")
    return 0 if table["rows"] else 1


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.command == "run":
            return cmd_run(args)
        return cmd_table1(args)
    except ConfigError as exc:
        print(f"gcs: configuration error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("gcs: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["build_parser", "main"]
