"""Delays every packet of a netfilter queue by a fixed time: a link delay for kernels without
sch_netem (nor sch_fq), from user space. An iptables rule ``-j NFQUEUE --queue-num N`` hands
the packets to this process, which gives each its ACCEPT verdict ``DELAY_MS`` after it arrived,
in order. Netlink is spoken directly (linux/netfilter/nfnetlink_queue.h): only the packet ids
are copied here, never the payloads.

    python delay_link.py QUEUE_NUM DELAY_MS

Prints ``bound`` once the queue is bound (add the iptables rule after it: packets queued with no
one listening are dropped), then runs until SIGTERM, printing the packets delayed on its way out.
"""

import collections
import signal
import socket
import struct
import sys
import time

NETLINK_NETFILTER = 12
NFNL_SUBSYS_QUEUE = 3
NFQNL_MSG_PACKET, NFQNL_MSG_VERDICT, NFQNL_MSG_CONFIG = 0, 1, 2
NFQA_PACKET_HDR, NFQA_VERDICT_HDR = 1, 2
NFQA_CFG_CMD, NFQA_CFG_PARAMS = 1, 2
NFQNL_CFG_CMD_BIND, NFQNL_COPY_META = 1, 1
NF_ACCEPT = 1
NLM_F_REQUEST, NLM_F_ACK = 1, 4
NLMSG_ERROR = 2


def attribute(kind: int, payload: bytes) -> bytes:
    length = 4 + len(payload)
    return struct.pack("=HH", length, kind) + payload + b"\0" * (-length % 4)


def message(kind: int, queue: int, attributes: bytes, flags: int = NLM_F_REQUEST) -> bytes:
    body = struct.pack("=BBH", socket.AF_INET, 0, socket.htons(queue)) + attributes
    return struct.pack("=IHHII", 16 + len(body), (NFNL_SUBSYS_QUEUE << 8) | kind, flags, 0, 0) + body


def bind(sock: socket.socket, queue: int) -> None:
    commands = (
        attribute(NFQA_CFG_CMD, struct.pack("!BxH", NFQNL_CFG_CMD_BIND, socket.AF_INET)),
        attribute(NFQA_CFG_PARAMS, struct.pack("!IB", 0, NFQNL_COPY_META)),
    )
    for command in commands:
        sock.send(message(NFQNL_MSG_CONFIG, queue, command, NLM_F_REQUEST | NLM_F_ACK))
        reply = sock.recv(4096)
        kind = struct.unpack_from("=H", reply, 4)[0]
        error = struct.unpack_from("=i", reply, 16)[0] if kind == NLMSG_ERROR else 0
        if error:
            raise OSError(-error, f"binding netfilter queue {queue}")


def packet_ids(data: bytes):
    """The packet ids in one read of the socket (several netlink messages may come at once)."""
    offset = 0
    while offset + 16 <= len(data):
        length, kind = struct.unpack_from("=IH", data, offset)
        if kind == (NFNL_SUBSYS_QUEUE << 8) | NFQNL_MSG_PACKET:
            position = offset + 20  # past nlmsghdr and nfgenmsg
            while position + 4 <= offset + length:
                size, attr = struct.unpack_from("=HH", data, position)
                if attr & 0x7FFF == NFQA_PACKET_HDR:
                    yield struct.unpack_from("!I", data, position + 4)[0]
                position += (size + 3) & ~3
        offset += (length + 3) & ~3


def main(queue: str, delay_ms: str) -> int:
    queue_num, delay_s = int(queue), float(delay_ms) / 1e3
    sock = socket.socket(socket.AF_NETLINK, socket.SOCK_RAW, NETLINK_NETFILTER)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    bind(sock, queue_num)
    print("bound", flush=True)
    running = [True]
    signal.signal(signal.SIGTERM, lambda *_: running.__setitem__(0, False))
    waiting = collections.deque()  # (release time, packet id), in arrival order
    delayed = 0
    while running[0]:
        now = time.monotonic()
        while waiting and waiting[0][0] <= now:
            _, packet = waiting.popleft()
            verdict = attribute(NFQA_VERDICT_HDR, struct.pack("!II", NF_ACCEPT, packet))
            sock.send(message(NFQNL_MSG_VERDICT, queue_num, verdict))
            delayed += 1
        sock.settimeout(max(0.0005, waiting[0][0] - now) if waiting else 0.1)
        try:
            data = sock.recv(1 << 16)
        except (TimeoutError, InterruptedError):
            continue
        arrived = time.monotonic()
        waiting.extend((arrived + delay_s, packet) for packet in packet_ids(data))
    print(f"delayed {delayed}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
