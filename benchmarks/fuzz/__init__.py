"""Hostile input against running processes while a real flight goes on; the entry
`benchmarks/fuzz_campaign.py` documents the campaign.

The parts: `config` (files, ports, limits), `traffic` (non-destructive hostile datagrams),
`gcs_messages` (messages the FCU obeys, with any field values), `gcs_sequences` (sequences
of them), `listener` (the listening link), `prober` (probes of the answers),
`sequence_campaign`, `flight` (a real-time flight and the sockets attacking it), `runner`
(one flight per port) and `report` (what is printed).
"""
