"""deploy/: systemd units, their command lines, logrotate, the Zenoh configs, the access generator, --zenoh-config."""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import json5
import pytest
import zenoh

from protocol.errors import ConfigError
from reckon import cli
from reckon.cli.bus import bus_config
from reckon.transport.bus import DEFAULT_ENDPOINT, zenoh_config_from_file

ROOT = Path(__file__).resolve().parents[2]
DEPLOY = ROOT / "deploy"
UNITS = ("reckon-hub.service", "reckon-edge@.service", "zenohd.service")
RECKON = Path(sys.executable).parent / "reckon"  # the venv's console script


def load_generator():
    spec = importlib.util.spec_from_file_location("make_venue_access", DEPLOY / "make-venue-access.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def unit_lines(name: str, key: str) -> list[str]:
    """Values of `key=` in a unit file, continuation lines joined."""
    text = (DEPLOY / "systemd" / name).read_text().replace("\\\n", " ")
    return [line.split("=", 1)[1] for line in text.splitlines() if line.startswith(f"{key}=")]


def env_file(path: Path) -> dict[str, str]:
    """KEY=value / KEY="value" lines of a systemd EnvironmentFile."""
    values = {}
    for line in path.read_text().splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            key, _, value = line.partition("=")
            values[key.strip()] = " ".join(shlex.split(value))
    return values


# ---------------------------------------------------------------------------------------------
# systemd units


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze is not installed")
def test_every_unit_passes_systemd_analyze_verify_without_a_warning(tmp_path):
    zenohd = tmp_path / "zenohd"  # a stand-in: zenohd is not installed here, verify only needs an executable
    zenohd.write_text("#!/bin/sh\n")
    zenohd.chmod(0o755)
    for name in UNITS:
        text = (DEPLOY / "systemd" / name).read_text()
        text = text.replace("/opt/reckon/venv/bin/reckon", str(RECKON)).replace("/usr/bin/zenohd", str(zenohd))
        (tmp_path / name).write_text(text)
    names = ["reckon-hub.service", "reckon-edge@chair1.service", "zenohd.service"]
    result = subprocess.run(["systemd-analyze", "verify", *(str(tmp_path / n) for n in names)],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    # verify only warns (exit 0) on unknown keys and bad values: any line about our files is a defect
    assert [line for line in result.stderr.splitlines() if str(tmp_path) in line] == []


def test_every_unit_restarts_on_failure_with_limits_and_is_hardened():
    for name in UNITS:
        assert unit_lines(name, "Restart") == ["on-failure"], name
        assert int(unit_lines(name, "StartLimitBurst")[0]) >= 3, name
        for key, value in (("NoNewPrivileges", "yes"), ("ProtectSystem", "strict"), ("PrivateTmp", "yes"),
                           ("ProtectHome", "yes"), ("CapabilityBoundingSet", "")):
            assert unit_lines(name, key) == [value], (name, key)
    for name in ("reckon-hub.service", "reckon-edge@.service"):
        assert unit_lines(name, "ReadWritePaths") == ["/var/lib/reckon"]
        assert unit_lines(name, "MemoryDenyWriteExecute") == []  # the edge's fallback JIT writes code


def parse_exec_start(name: str, instance: str = "chair1", env: dict[str, str] | None = None):
    """ExecStart of a reckon unit as systemd would run it, parsed by reckon's own argument parser."""
    (command,) = unit_lines(name, "ExecStart")
    command = command.replace("%i", instance)
    for key, value in (env or {}).items():
        command = command.replace(f"${key}", value)  # unbraced $VAR: systemd splits it into words
    argv = shlex.split(command)
    assert argv[0] == "/opt/reckon/venv/bin/reckon"
    return cli.build_parser().parse_args(argv[1:])


def test_the_hubs_command_line_is_valid_and_uses_the_deploy_paths():
    args = parse_exec_start("reckon-hub.service")
    assert (args.venue, args.output, args.zenoh_config) == (
        "/etc/reckon/venue.toml", "/var/lib/reckon/recordings/hub.mcap", "/etc/reckon/zenoh/hub.json5")
    assert (args.listen, args.connect, args.mode) == ([], [], None)  # the endpoints are the file's


def test_the_edges_command_line_with_the_example_env_file_is_valid():
    (env_path,) = unit_lines("reckon-edge@.service", "EnvironmentFile")
    assert env_path == "/etc/reckon/edge/%i.env"
    env = env_file(DEPLOY / "edge" / "example.env")
    args = parse_exec_start("reckon-edge@.service", "chair1", env)
    assert args.agent == "chair1" and args.zenoh_config == "/etc/reckon/zenoh/edge-chair1.json5"
    assert args.source == ["chair1-seat=serial:///dev/ttyACM0?baud=115200", "chair1-left=serial:///dev/ttyACM1?baud=115200",
                           "chair1-right=serial:///dev/ttyACM2?baud=115200"]
    assert args.pose_rate == 50.0


def test_zenohd_runs_the_router_config():
    (command,) = unit_lines("zenohd.service", "ExecStart")
    assert shlex.split(command) == ["/usr/bin/zenohd", "--config", "/etc/reckon/zenoh/router.json5"]


def run_exec_start_pre(state: Path) -> None:
    (command,) = unit_lines("reckon-hub.service", "ExecStartPre")
    command = command.replace("%%", "%").replace("/var/lib/reckon", str(state))
    subprocess.run(shlex.split(command), check=True, timeout=30)


def test_a_hub_restart_keeps_the_previous_recording_under_logrotates_name(tmp_path):
    recordings = tmp_path / "recordings"
    recordings.mkdir()
    run_exec_start_pre(tmp_path)  # nothing there yet: nothing to do
    assert list(recordings.iterdir()) == []
    (recordings / "hub.mcap").write_bytes(b"")
    run_exec_start_pre(tmp_path)  # an empty file (a hub that never wrote) is not worth keeping
    assert [p.name for p in recordings.iterdir()] == ["hub.mcap"]
    (recordings / "hub.mcap").write_bytes(b"recording")
    run_exec_start_pre(tmp_path)
    (kept,) = recordings.iterdir()
    assert re.fullmatch(r"hub\.mcap-\d{8}-\d{9,}", kept.name) and kept.read_bytes() == b"recording"


@pytest.mark.skipif(shutil.which("logrotate") is None, reason="logrotate is not installed")
def test_logrotate_renames_the_recording_restarts_the_hub_and_keeps_30(tmp_path):
    recordings = tmp_path / "recordings"
    recordings.mkdir()
    for day in range(1, 31):  # 30 older ones, as logrotate or a hub restart named them
        (recordings / f"hub.mcap-202611{day:02d}-17{day:08d}").write_bytes(b"old")
    (recordings / "hub.mcap").write_bytes(b"today")
    marker = tmp_path / "restarted"
    config = (DEPLOY / "logrotate" / "reckon").read_text()
    config = config.replace("/var/lib/reckon", str(tmp_path)).replace("su reckon reckon", "")  # no such user here
    config = config.replace("systemctl try-restart reckon-hub.service", f"touch {marker}")
    (tmp_path / "reckon.conf").write_text(config)
    os.chmod(tmp_path / "reckon.conf", 0o644)  # logrotate refuses a group- or world-writable config
    result = subprocess.run(["logrotate", "--force", "--state", str(tmp_path / "state"), str(tmp_path / "reckon.conf")],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    names = sorted(p.name for p in recordings.iterdir())
    assert "hub.mcap" not in names and len(names) == 30 and marker.exists()
    assert "hub.mcap-20261101-1700000001" not in names  # the oldest went
    assert sum((recordings / n).read_bytes() == b"today" for n in names) == 1


# ---------------------------------------------------------------------------------------------
# Zenoh configs


@pytest.mark.parametrize("name", ["router.json5", "hub.json5", "edge.json5"])
def test_the_deploy_zenoh_configs_parse_with_zenoh(name):
    config = zenoh.Config.from_file(str(DEPLOY / "zenoh" / name))
    mode = "router" if name == "router.json5" else "client"
    assert json.loads(config.get_json("mode")) == mode
    endpoints = json.loads(config.get_json("listen/endpoints" if mode == "router" else "connect/endpoints"))
    assert endpoints and all(e.startswith("tls/") for e in endpoints)
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False


def test_the_shipped_router_acl_is_the_generators_output_for_its_example_venue():
    shipped = json5.loads((DEPLOY / "zenoh" / "router.json5").read_text())
    assert shipped["access_control"] == load_generator().access_control({"court1": ["chair1", "chair2"]})


def test_the_generator_writes_credentials_that_match_and_keeps_them_on_a_rerun(tmp_path):
    generator = load_generator()
    out = tmp_path / "access"
    venue_file = ROOT / "docs" / "examples" / "csv-session" / "session.toml"  # demo-court, agent chair1
    generator.main(["--venue", str(venue_file), "--venue", "court2=a1,a2", "--peer-router", "router.b", "-o", str(out)])
    users = generator.read_users(out / "users.txt")
    assert set(users) == {"hub.demo-court", "edge.demo-court.chair1", "hub.court2", "edge.court2.a1",
                          "edge.court2.a2", "router.b"}
    for venue, name, user in (("demo-court", "edge-chair1", "edge.demo-court.chair1"), ("court2", "hub", "hub.court2")):
        path = out / venue / f"{name}.json5"
        assert json5.loads(path.read_text())["transport"]["auth"]["usrpwd"] == {"user": user, "password": users[user]}
        assert path.stat().st_mode & 0o777 == 0o640  # it holds a password
        zenoh.Config.from_file(str(path))
    router = zenoh.Config.from_file(str(out / "router.json5"))
    subjects = json.loads(router.get_json("access_control/subjects"))
    assert {s["id"] for s in subjects} == set(users)
    generator.main(["--venue", "court2=a1,a2,a3", "-o", str(out)])  # a new agent: the others keep their passwords
    again = generator.read_users(out / "users.txt")
    assert all(again[user] == password for user, password in users.items()) and "edge.court2.a3" in again


def test_the_generator_refuses_a_bad_agent_id(tmp_path):
    with pytest.raises(SystemExit, match="chair/1"):
        load_generator().main(["--venue", "court1=chair/1", "-o", str(tmp_path)])


# ---------------------------------------------------------------------------------------------
# zenoh_config_from_file and the CLI's --zenoh-config


def write(path: Path, document: dict) -> Path:
    path.write_text(json.dumps(document))
    return path


def test_a_file_keeps_scouting_off_and_timestamping_on_unless_it_says_otherwise(tmp_path):
    config = zenoh_config_from_file(write(tmp_path / "a.json5", {"mode": "client", "connect": {"endpoints": [DEFAULT_ENDPOINT]}}))
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False
    assert json.loads(config.get_json("scouting/gossip/enabled")) is False
    assert json.loads(config.get_json("timestamping/enabled")) is True
    config = zenoh_config_from_file(write(tmp_path / "b.json5", {"scouting": {"multicast": {"enabled": True}},
                                                                  "timestamping": {"enabled": False}}))
    assert json.loads(config.get_json("scouting/multicast/enabled")) is True
    assert json.loads(config.get_json("scouting/gossip/enabled")) is False
    assert json.loads(config.get_json("timestamping/enabled")) is False


def test_command_line_endpoints_and_mode_replace_the_files(tmp_path):
    path = write(tmp_path / "c.json5", {"mode": "client", "connect": {"endpoints": ["tls/hub.local:7447"]}})
    args = cli.build_parser().parse_args(["edge", "--agent", "a", "--source", "mcap://x.mcap", "--zenoh-config", str(path)])
    config = bus_config(args, "connect")
    assert (json.loads(config.get_json("mode")), json.loads(config.get_json("connect/endpoints"))) == (
        "client", ["tls/hub.local:7447"])
    args = cli.build_parser().parse_args(["edge", "--agent", "a", "--source", "mcap://x.mcap", "--zenoh-config", str(path),
                                          "--connect", "tcp/10.0.0.2:7447", "--mode", "peer"])
    config = bus_config(args, "connect")
    assert (json.loads(config.get_json("mode")), json.loads(config.get_json("connect/endpoints"))) == (
        "peer", ["tcp/10.0.0.2:7447"])


def test_without_a_file_the_embedded_default_is_unchanged():
    args = cli.build_parser().parse_args(["hub", "--venue", "v.toml"])
    config = bus_config(args, "listen")
    assert json.loads(config.get_json("mode")) == "peer"
    assert json.loads(config.get_json("listen/endpoints")) == [DEFAULT_ENDPOINT]


@pytest.mark.parametrize("name, text, message", [
    ("missing.json5", None, "cannot read it"),
    ("broken.json5", "{mode: 'peer', ", "not valid JSON5"),
    ("list.json5", "[1, 2]", "expected an object"),
    ("unknown.json5", "{mode: 'peer', modes: 1}", "unknown field `modes`"),
    ("badtype.json5", "{transport: {link: {tls: {root_ca_certificate: 3}}}}", "expected a string"),
    ("config.yaml", "mode: peer", "expected a .json5 or .json file"),
    ("nocert.json5", "{transport: {link: {tls: {root_ca_certificate: '/nowhere/ca.pem'}}}}",
     "transport/link/tls/root_ca_certificate names '/nowhere/ca.pem', which is not a file"),
])
def test_a_bad_file_is_refused_naming_the_file_and_the_problem(tmp_path, name, text, message):
    path = tmp_path / name
    if text is not None:
        path.write_text(text)
    with pytest.raises(ConfigError) as raised:
        zenoh_config_from_file(path)
    assert str(path) in str(raised.value) and message in str(raised.value)
    assert ".rs:" not in str(raised.value)  # Zenoh's Rust source location is noise to an operator


def test_a_bad_override_is_refused(tmp_path):
    path = write(tmp_path / "d.json5", {"mode": "client"})
    with pytest.raises(ConfigError, match="'localhost:7447' is not <protocol>/<address>"):
        zenoh_config_from_file(path, connect=["localhost:7447"])
    with pytest.raises(ConfigError, match="'relay' is not one of"):
        zenoh_config_from_file(path, mode="relay")


def test_the_deploy_client_configs_name_their_missing_certificate(tmp_path):
    with pytest.raises(ConfigError, match="edge.json5: transport/link/tls/root_ca_certificate names '/etc/reckon/tls/ca.pem'"):
        zenoh_config_from_file(DEPLOY / "zenoh" / "edge.json5")


# ---------------------------------------------------------------------------------------------
# certificates


@pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl is not installed")
def test_make_certs_signs_the_router_for_its_names_and_never_overwrites(tmp_path):
    script = str(DEPLOY / "make-certs.sh")
    subprocess.run([script, str(tmp_path), "ca"], check=True, capture_output=True, timeout=60)
    subprocess.run([script, str(tmp_path), "server", "router", "hub.local", "192.168.1.10"], check=True,
                   capture_output=True, timeout=60)
    subprocess.run([script, str(tmp_path), "client", "edge1"], check=True, capture_output=True, timeout=60)
    for name in ("router", "edge1"):
        verified = subprocess.run(["openssl", "verify", "-CAfile", str(tmp_path / "ca.pem"), str(tmp_path / f"{name}.pem")],
                                  capture_output=True, text=True, timeout=60)
        assert verified.returncode == 0, verified.stderr
        assert (tmp_path / f"{name}.key").stat().st_mode & 0o077 == 0  # private keys: owner only
    text = subprocess.run(["openssl", "x509", "-in", str(tmp_path / "router.pem"), "-noout", "-ext", "subjectAltName"],
                          capture_output=True, text=True, check=True, timeout=60).stdout
    assert "DNS:hub.local" in text and "IP Address:192.168.1.10" in text
    before = (tmp_path / "ca.pem").read_bytes()
    again = subprocess.run([script, str(tmp_path), "ca"], capture_output=True, text=True, timeout=60)
    assert again.returncode == 1 and "not overwritten" in again.stderr and (tmp_path / "ca.pem").read_bytes() == before


# ---------------------------------------------------------------------------------------------
# install.sh


def test_install_sh_is_valid_shell_and_installs_only_files_that_exist():
    for script in ("install.sh", "make-certs.sh"):
        checked = subprocess.run(["sh", "-n", str(DEPLOY / script)], capture_output=True, text=True, timeout=30)
        assert checked.returncode == 0, checked.stderr
        assert os.access(DEPLOY / script, os.X_OK)
    text = (DEPLOY / "install.sh").read_text()
    installed = re.findall(r'"\$clone/(deploy/[^"]+)"', text)
    assert {"deploy/systemd/reckon-hub.service", "deploy/systemd/reckon-edge@.service", "deploy/systemd/zenohd.service",
            "deploy/logrotate/reckon", "deploy/journald/reckon.conf", "deploy/edge/example.env"} <= set(installed)
    assert [path for path in installed if not (ROOT / path).exists()] == []
    # every place a unit writes or reads its settings from is one install.sh makes
    for path in ("/var/lib/reckon/recordings", "/var/lib/reckon/spool",
                 "/etc/reckon/zenoh", "/etc/reckon/tls", "/etc/reckon/edge"):
        assert path in text, path


def installed_extras(*flags: str) -> subprocess.CompletedProcess:
    """What install.sh asks pip for with these flags: its argument handling, run up to the root check."""
    text = (DEPLOY / "install.sh").read_text()
    start, end = text.index("hub=no\n"), text.index('[ "$(id -u)" -eq 0 ]')
    return subprocess.run(["sh", "-c", text[start:end] + 'echo "$extras"', "install.sh", *flags],
                          capture_output=True, text=True, timeout=30)


@pytest.mark.parametrize("flags, extras", [
    ((), "hub,edge"), (("--hub",), "hub"), (("--edge", "--serial"), "edge"), (("--edge", "--ble"), "edge"),
    (("--hub", "--edge", "--serial", "--ble", "--no-units"), "hub,edge"), (("--serial",), "hub,edge"),
])
def test_install_sh_installs_the_runtime_extras_of_the_machines_role(flags, extras):
    result = installed_extras(*flags)
    assert (result.returncode, result.stdout.strip()) == (0, extras), result.stderr
    assert '"$prefix/venv/bin/pip" install --upgrade "$clone[$extras]"' in (DEPLOY / "install.sh").read_text()
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert set(extras.split(",")) <= set(declared)


def test_install_sh_refuses_devices_on_a_hub_only_machine():
    result = installed_extras("--hub", "--serial")
    assert result.returncode == 2 and "add --edge" in result.stderr
