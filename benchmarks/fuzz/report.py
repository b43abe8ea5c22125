"""What the campaign prints: per flight, per spoofing attack, and per port's summary."""

from __future__ import annotations

from typing import Any

from benchmarks.fuzz.config import ERR_POS_LIMIT_M
from fcu.edge.telemetry import LINK_BUDGET_MSG_S


def counts_text(d: dict[Any, Any]) -> str:
    """{"a": 1, "b": 2} as "a 1, b 2"."""
    return ", ".join(f"{k} {v}" for k, v in d.items())


def report_port(r: dict[str, Any]) -> bool:
    """The flight's report; True when it kept its mission under the non-destructive
    attack (the sequence campaign that follows on the GCS ports changes it at will)."""
    d, a, st = r["during"], r["after"], r["stats"]
    fcu, sitl = st["fcu"], st["sitl"]
    mission_kept = d["mission_totals"] == a["mission_totals"] == [r["mission_items"]] and \
        d["mission_active"] and a["mission_active"]
    ok = not r["crashed"] and d["err_pos_max_m"] < ERR_POS_LIMIT_M and \
        a["err_pos_max_m"] < ERR_POS_LIMIT_M and not d["disarmed"] and \
        a["heartbeat_gap_max_s"] < 2.0 and mission_kept
    print(f"== {r['port']}: {r['inputs']} inputs in {r['seconds']:.1f} s "
          f"({r['inputs'] / max(r['seconds'], 1e-9):.0f}/s)")
    if r["inputs"]:
        print(f"   by category: {counts_text(dict(sorted(r['by_category'].items())))}")
    if r["direct_to_fcu_sim_port"]:
        print(f"   of which {r['direct_to_fcu_sim_port']} straight to the FCU's sim port from "
              "other sockets (dropped by its link), the rest through the relay")
    if r["not_sent_buffer_full"]:
        print(f"   not sent (our socket buffer full): {r['not_sent_buffer_full']}")
    print(f"   crashed: {r['crashed_end'] or 'none'}; exit codes {st['exit_codes']}")
    print(f"   FCU: {fcu.get('steps')} steps, {fcu.get('deadline_misses')} deadline misses, "
          f"{fcu.get('rejected_bytes')} bytes rejected, {fcu.get('ignored_messages')} "
          f"messages ignored, {fcu.get('signing_rejects')} refused by signing, "
          f"{fcu.get('internal_errors')} internal errors")
    if sitl:
        print(f"   SITL: {sitl['rejected_bytes']} bytes rejected, "
              f"{sitl['ignored_answers']} answers ignored")
    print(f"   during: ERR_POS max {d['err_pos_max_m']:.4f} m ({d['err_pos_samples']} "
          f"samples), heartbeat gap max {d['heartbeat_gap_max_s']:.2f} s, SYS_STATUS "
          f"errors_comm {d['errors_comm']}, disarmed {d['disarmed']}")
    print(f"   after:  ERR_POS max {a['err_pos_max_m']:.4f} m, heartbeat gap max "
          f"{a['heartbeat_gap_max_s']:.2f} s")
    if d["texts"]:
        print(f"   STATUSTEXT: {sorted(set(d['texts']))[:6]}")
    print(f"   mission: {r['mission_items']} items uploaded; MISSION_CURRENT totals during "
          f"{d['mission_totals']}, after {a['mission_totals']}; active throughout "
          f"{d['mission_active'] and a['mission_active']}")
    print(f"   flight kept its mission: {'yes' if ok else 'NO'}")
    s = r["sequences"]
    if s is not None:
        print(f"   sequence campaign: {s['inputs']} inputs in {s['seconds']:.1f} s "
              f"({s['inputs'] / max(s['seconds'], 1e-9):.0f}/s; probes took "
              f"{s['probe_seconds']:.1f} s more), {s['in_sequences']} of them in "
              f"{sum(s['sequences'].values())} sequences "
              f"({counts_text(dict(sorted(s['sequences'].items())))})")
        print(f"   inputs by category: {counts_text(dict(sorted(s['by_category'].items())))}"
              + (f"; not sent (our socket buffer full): {s['not_sent']}" if s["not_sent"]
                 else ""))
        print(f"   probes: {s['probes']}; link 1 streams asked at 1 kHz: max "
              f"{s['link1_stream_msg_s_max']} msg/s (budget {LINK_BUDGET_MSG_S:.0f})")
        for line in s["probe_failures"][:12]:
            print(f"     {line}")
        for line in s["internal_errors"]:
            print(line if line.startswith("      ") else f"   internal errors: {line}")
    li = r["listen"]
    print(f"   listening link: {li['heartbeats']} heartbeats in {li['seconds']:.0f} s, longest "
          f"gap {li['gap_max_s']:.2f} s (at +{li['gap_at_s']:.0f} s); {li['msg_s']:.0f} msg/s "
          f"(max {li['msg_s_max']} in one second), streams {li['stream_msg_s']:.0f} msg/s "
          f"(max {li['stream_msg_s_max']}); top {counts_text(li['top_msg_s'])}")
    print(f"   live state seen there: {li['arm_changes']} arm/disarm changes, modes "
          f"{', '.join(li['modes']) or '-'}")
    if r["fcu_log_tail"]:
        print("   fcu log (end):")
        for line in r["fcu_log_tail"].splitlines()[-40:]:
            print(f"     | {line}")
    return ok


def report_spoof(r: dict[str, Any]) -> None:
    d, st = r["during_and_after"], r["stats"]
    what = {"states": "ODOMETRY from system 42 through the simulator link (3 m away)",
            "commands": "HIL_ACTUATOR_CONTROLS from system 42 to the simulator (rotors off)"}
    print(f"== spoof: {r['sent']} x {what[r['attack']]} in {r['seconds']:.1f} s")
    print(f"   crashed: {r['crashed'] or 'none'}; ERR_POS max {d['err_pos_max_m']:.3f} m, "
          f"disarmed {d['disarmed']}, STATUSTEXT {sorted(set(d['texts']))[:4]}")
    print(f"   FCU: {st['fcu'].get('deadline_misses')} deadline misses, "
          f"{st['fcu'].get('ignored_messages')} messages ignored; SITL: "
          f"{st['sitl'].get('ignored_answers')} answers ignored; ignored as it should: "
          f"{'yes' if d['err_pos_max_m'] < ERR_POS_LIMIT_M and not d['disarmed'] else 'NO'}")


def summarize(r: dict[str, Any], mission_ok: bool, gap_limit: float) -> list[str]:
    """The port's summary; returns what failed (empty: passed)."""
    fcu, li, s = r["stats"]["fcu"], r["listen"], r["sequences"]
    code = r["stats"]["exit_codes"].get("fcu")
    total = r["inputs"] + (s["inputs"] if s else 0)
    failed = []
    if not r["fcu_alive"]:
        failed.append(f"the fcu died (exit code {code})")
    internal = fcu.get("internal_errors")
    if internal is None:
        failed.append("no FCU statistics")
    elif internal:
        failed.append(f"internal_errors {internal}")
    if li["gap_max_s"] >= gap_limit:
        failed.append(f"HEARTBEAT gap {li['gap_max_s']:.2f} s on the listening link")
    if s and s["probes_failed"]:
        failed.append(f"{s['probes_failed']} probes failed")
    if not mission_ok:
        failed.append("the flight left its mission under the non-destructive attack")
    print(f"== summary {r['port']}")
    if s:
        print(f"   inputs sent: {total} ({r['inputs']} non-destructive, {s['inputs']} in the "
              f"sequence campaign); sequences: {sum(s['sequences'].values())} holding "
              f"{s['in_sequences']} inputs ({100 * s['in_sequences'] / max(total, 1):.0f} %)")
    else:
        print(f"   inputs sent: {total}; sequences: 0")
    print(f"   fcu alive: {'yes' if r['fcu_alive'] else 'NO'} (exit code {code}"
          f"{' after SIGTERM' if r['fcu_alive'] else ''})")
    print(f"   FCU stats: internal_errors {internal}, ignored_messages "
          f"{fcu.get('ignored_messages')}, rejected_bytes {fcu.get('rejected_bytes')}")
    print(f"   listening link: longest HEARTBEAT gap {li['gap_max_s']:.2f} s (bound "
          f"{gap_limit:g} s), {li['msg_s']:.0f} msg/s received (max {li['msg_s_max']} in one "
          f"second; streams {li['stream_msg_s']:.0f} msg/s, max {li['stream_msg_s_max']})")
    print(f"   verdict: {'OK' if not failed else 'FAILED: ' + '; '.join(failed)}")
    return failed
