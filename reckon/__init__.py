"""The reckon application around the cores: the one CLI (cli/), the edge and hub processes
(processes/), Zenoh and session logs in motion (transport/), importers, offline evaluation, the
live court view (web/), operator tools and benchmarks."""
