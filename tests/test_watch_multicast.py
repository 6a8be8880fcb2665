"""IEC 61162-450 multicast, inside a network namespace this test makes (``unshare -rn``:
its own loopback, no other interface): ``dracc watch udp://239.192.0.1:PORT
--join-multicast`` joins the group and hears what is sent to it; without the flag the
watch refuses the group with one clear message.  Nothing here joins a group on the host
network: the refusal happens before any socket is made."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
GROUP = "239.192.0.1"  #: IEC 61162-450 MISC group
PORT = 60001

SENDER = f"""
import socket, struct, subprocess, sys, time, json
from pathlib import Path
status = Path(sys.argv[1])
watch = subprocess.Popen([sys.executable, "-m", "dracc", "watch", "udp://{GROUP}:{PORT}",
    "--join-multicast", "--status", str(status), "--status-every", "0.1s",
    "--duration", "4s", "--no-analysis"], stderr=subprocess.PIPE)
end = time.monotonic() + 15
while not status.exists() and time.monotonic() < end:
    time.sleep(0.05)
tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
line = b"\\\\s:GP0001,c:1764547200*5F\\\\$GPGGA,000000,5436.000,N,02000.000,E,1,08,0.9,10.0,M,30.0,M,,*48"
for i in range(50):
    tx.sendto(b"UdPbC\\x00" + line + b"\\r\\n", ("{GROUP}", {PORT}))
    time.sleep(0.01)
_, err = watch.communicate(timeout=30)
print(json.dumps({{"code": watch.returncode, "stderr": err.decode()}}))
"""


def _can_unshare() -> bool:
    if not shutil.which("unshare") or not shutil.which("ip"):
        return False
    r = subprocess.run(["unshare", "-rn", "true"], capture_output=True)
    return r.returncode == 0


@pytest.mark.skipif(not _can_unshare(), reason="no user/network namespaces here (unshare -rn)")
def test_join_multicast_in_a_private_network_namespace(tmp_path):
    status = tmp_path / "status.json"
    script = tmp_path / "sender.py"
    script.write_text(SENDER)
    setup = "ip link set lo up && ip route add 224.0.0.0/4 dev lo && "
    r = subprocess.run(
        ["unshare", "-rn", "sh", "-c", setup + f'"{sys.executable}" {script} {status}'],
        capture_output=True,
        cwd=REPO,
        timeout=60,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/sbin:/usr/bin:/bin:/sbin"},
    )
    assert r.returncode == 0, r.stderr.decode()
    out = json.loads(r.stdout.decode().strip().splitlines()[-1])
    assert out["code"] == 0, out["stderr"]
    st = json.loads(status.read_text())
    assert st["received"] == 50 and st["sources"]["GP0001"]["records"] == 50


def test_multicast_group_refused_without_the_flag(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "dracc", "watch", f"udp://{GROUP}:{PORT}", "--duration", "1s"],
        capture_output=True,
        cwd=REPO,
        timeout=60,
    )
    err = r.stderr.decode()
    assert r.returncode == 3, err
    assert "multicast group" in err and "--join-multicast" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
