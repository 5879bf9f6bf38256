#!/usr/bin/env python3
"""A chamber controller served by pymodbus, for conformance tests of imucal's Modbus driver.

The Modbus side (request decoding, the TCP and RTU framing, exception replies, the register store,
float packing) is Debian's python3-pymodbus (3.0), an implementation imucal did not write. This
script only loads the chamber's register map from the same imucal-chamber-map/1 JSON the driver
reads (so the map is never written twice) and adds test controls on stdin.

Usage: pymodbus_chamber.py --map MAP.json [--tcp-port N] [--rtu] [--initial-C T]
  --tcp-port 0 picks a free port. --rtu serves Modbus RTU on a pseudo-terminal instead and prints
  the device path the driver opens. The first stdout line is JSON: {"tcp_port": N} or
  {"rtu_device": "/dev/pts/N"}.

Controls, one command a line on stdin, each answered by one JSON line on stdout:
  get NAME            value of setpoint|process_value|working_setpoint decoded by pymodbus's
                      BinaryPayloadDecoder, with the raw registers
  set NAME VALUE      encode VALUE (device unit) with pymodbus's BinaryPayloadBuilder and store it
  raw ADDRESS COUNT   raw holding registers
  poke ADDRESS VALUE  store one raw 16-bit register (alarms, units, control mode)
  coil ADDRESS        one of the 8 coils (digital outputs; a power relay writes them)
  fcs                 the function codes of the requests served since the last `fcs`
  exception ADDRESS CODE  answer every request touching ADDRESS with Modbus exception CODE
  clear-exceptions
  drop-after N        answer N more requests, then close the connection instead of answering
                      the next one (once; over RTU the next one is left unanswered)
  drop-now            close every open connection at once
  follow RATE         the process value moves towards the set point at RATE per second
  quit
The server exits when stdin closes, so it never outlives the test that started it.
"""

import argparse
import asyncio
import json
import logging
import os
import sys
import termios
import tty

from pymodbus.constants import Endian
from pymodbus.datastore import (
    ModbusSequentialDataBlock,
    ModbusServerContext,
    ModbusSlaveContext,
)
from pymodbus.framer.rtu_framer import ModbusRtuFramer
from pymodbus.payload import BinaryPayloadBuilder, BinaryPayloadDecoder
from pymodbus.server.async_io import (
    ModbusConnectedRequestHandler,
    ModbusSerialServer,
    ModbusSingleRequestHandler,
    ModbusTcpServer,
)

# (byte order inside a word, word order) for each name imucal's maps use.
WORD_ORDERS = {
    "ABCD": (Endian.Big, Endian.Big),
    "high_word_first": (Endian.Big, Endian.Big),
    "CDAB": (Endian.Big, Endian.Little),
    "low_word_first": (Endian.Big, Endian.Little),
    "BADC": (Endian.Little, Endian.Big),
    "high_word_first_swapped": (Endian.Little, Endian.Big),
    "DCBA": (Endian.Little, Endian.Little),
    "low_word_first_swapped": (Endian.Little, Endian.Little),
}


class NoRegisters(ModbusSequentialDataBlock):
    """A table the controller does not have: every access is an illegal data address (exception
    2), so a driver using the wrong function code fails loudly instead of reading zeros."""

    def __init__(self):
        super().__init__(0, [0])

    def validate(self, address, count=1):
        return False


class ChamberMap:
    """The parts of an imucal-chamber-map/1 file this server needs."""

    def __init__(self, doc):
        self.slave_id = doc.get("slave_id", 1)
        value = doc["value"]
        self.float32 = value["type"] == "float32"
        if self.float32:
            self.byteorder, self.wordorder = WORD_ORDERS[value["word_order"]]
            self.width = 2
        else:
            self.scale = float(value["scale"])
            self.width = 1
        self.values = {"process_value": doc["process_value"], "setpoint": doc["setpoint"]}
        for key in ("working_setpoint", "ramp_rate_per_min"):
            if doc.get(key) is not None:
                self.values[key] = doc[key]
        self.units = doc.get("units")
        self.control_mode = doc.get("control_mode")
        self.alarms = doc.get("alarms", [])
        singles = [a["address"] for a in self.alarms]
        for reg in (self.units, self.control_mode):
            if reg:
                singles.append(reg["address"])
        self.size = max([a + self.width for a in self.values.values()] + [a + 1 for a in singles])

    def encode(self, value):
        if self.float32:
            builder = BinaryPayloadBuilder(byteorder=self.byteorder, wordorder=self.wordorder)
            builder.add_32bit_float(value)
            return builder.to_registers()
        scaled = round(value * self.scale)
        if not -32768 <= scaled <= 32767:
            raise ValueError(f"{value} does not fit an int16 scaled by {self.scale}")
        return [scaled & 0xFFFF]

    def decode(self, registers):
        if self.float32:
            decoder = BinaryPayloadDecoder.fromRegisters(
                registers, byteorder=self.byteorder, wordorder=self.wordorder
            )
            return decoder.decode_32bit_float()
        raw = registers[0]
        return (raw - 0x10000 if raw & 0x8000 else raw) / self.scale


class Controls:
    """State shared between the request handlers and the stdin commands (one event loop)."""

    def __init__(self, chamber_map, store):
        self.map = chamber_map
        self.store = store
        self.function_codes = []
        self.exceptions = {}  # register address -> Modbus exception code
        self.drop_after = None  # requests still answered before the connection is dropped
        self.follow_rate_per_s = None
        self.connections = []  # open TCP transports

    def holding(self, address, count):
        return self.store.getValues(3, address, count)

    def set_holding(self, address, values):
        self.store.setValues(3, address, values)

    def get(self, name):
        address = self.map.values[name]
        regs = self.holding(address, self.map.width)
        return self.map.decode(regs), regs

    def set(self, name, value):
        self.set_holding(self.map.values[name], self.map.encode(value))


def request_span(request):
    """First register and count a request touches (write-single requests carry no count)."""
    return request.address, getattr(request, "count", 1) or 1


def make_handler(base, controls, connected):
    """`connected`: TCP, where dropping closes the connection; on a serial line, where there is
    no connection to close, the dropped request is left unanswered instead."""

    class Handler(base):
        def execute(self, request, *addr):
            controls.function_codes.append(request.function_code)
            if controls.drop_after is not None:
                if controls.drop_after == 0:
                    controls.drop_after = None
                    if connected:
                        self.transport.close()
                    return
                controls.drop_after -= 1
            first, count = request_span(request)
            for address, code in controls.exceptions.items():
                if first <= address < first + count:
                    response = request.doException(code)
                    response.transaction_id = request.transaction_id
                    response.unit_id = request.unit_id
                    self.send(response, *addr)
                    return
            super().execute(request, *addr)

        def connection_made(self, transport):
            super().connection_made(transport)
            controls.connections.append(transport)

        def connection_lost(self, call_exc):
            if self.transport in controls.connections:
                controls.connections.remove(self.transport)
            super().connection_lost(call_exc)

    return Handler


def initial_registers(chamber_map, initial):
    regs = [0] * chamber_map.size
    for name in ("process_value", "setpoint", "working_setpoint"):
        if name in chamber_map.values:
            address = chamber_map.values[name]
            regs[address : address + chamber_map.width] = chamber_map.encode(initial)
    if chamber_map.units:
        regs[chamber_map.units["address"]] = chamber_map.units["C"]
    if chamber_map.control_mode:
        regs[chamber_map.control_mode["address"]] = chamber_map.control_mode["off"]
    for alarm in chamber_map.alarms:
        regs[alarm["address"]] = alarm["normal"][0] if "normal" in alarm else 0
    return regs


def run_command(controls, words):
    cmd, args = words[0], words[1:]
    if cmd == "get":
        value, regs = controls.get(args[0])
        return {"value": value, "registers": regs}
    if cmd == "set":
        controls.set(args[0], float(args[1]))
        return {"ok": True}
    if cmd == "raw":
        return {"registers": controls.holding(int(args[0]), int(args[1]))}
    if cmd == "poke":
        controls.set_holding(int(args[0]), [int(args[1]) & 0xFFFF])
        return {"ok": True}
    if cmd == "coil":
        return {"value": bool(controls.store.getValues(1, int(args[0]), 1)[0])}
    if cmd == "fcs":
        seen, controls.function_codes = controls.function_codes, []
        return {"function_codes": seen}
    if cmd == "exception":
        controls.exceptions[int(args[0])] = int(args[1])
        return {"ok": True}
    if cmd == "clear-exceptions":
        controls.exceptions.clear()
        return {"ok": True}
    if cmd == "drop-after":
        controls.drop_after = int(args[0])
        return {"ok": True}
    if cmd == "drop-now":
        for transport in list(controls.connections):
            transport.close()
        return {"ok": True, "dropped": len(controls.connections)}
    if cmd == "follow":
        controls.follow_rate_per_s = float(args[0])
        return {"ok": True}
    raise ValueError(f"unknown command '{cmd}'")


async def follow_setpoint(controls):
    """The air moves towards the set point at a fixed rate: enough to see a reading follow."""
    period_s = 0.02
    while True:
        await asyncio.sleep(period_s)
        if controls.follow_rate_per_s is None:
            continue
        pv, _ = controls.get("process_value")
        sp, _ = controls.get("setpoint")
        step = controls.follow_rate_per_s * period_s
        pv = sp if abs(sp - pv) <= step else pv + (step if sp > pv else -step)
        controls.set("process_value", pv)
        if "working_setpoint" in controls.map.values:
            controls.set("working_setpoint", sp)


def say(obj):
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


async def serve_stdin(controls):
    loop = asyncio.get_running_loop()
    reader = asyncio.StreamReader()
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)
    while True:
        line = await reader.readline()
        if not line:
            return  # the test went away
        words = line.decode().split()
        if not words:
            continue
        if words[0] == "quit":
            return
        try:
            say(run_command(controls, words))
        except Exception as exc:  # a bad command is the test's bug: report it, keep serving
            say({"error": f"{type(exc).__name__}: {exc}"})


def raw_pty():
    """A pseudo-terminal pair in raw mode. pymodbus's serial server opens the device end through
    pyserial; the driver opens the other device of a second pair and the two masters are joined,
    since a pty has only one device end and both sides want a device path."""
    master, device = os.openpty()
    tty.setraw(device)
    attrs = termios.tcgetattr(device)
    attrs[3] &= ~termios.ECHO
    termios.tcsetattr(device, termios.TCSANOW, attrs)
    return master, device


def join_masters(loop, a, b):
    def pump(src, dst):
        try:
            data = os.read(src, 4096)
        except OSError:  # the device end is closed (the driver reconnects): keep going
            return
        if data:
            os.write(dst, data)

    loop.add_reader(a, pump, a, b)
    loop.add_reader(b, pump, b, a)


async def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", required=True, help="imucal-chamber-map/1 JSON file")
    parser.add_argument("--tcp-port", type=int, default=0)
    parser.add_argument("--rtu", action="store_true", help="serve RTU on a pseudo-terminal")
    parser.add_argument("--initial-C", type=float, default=22.0, dest="initial")
    parser.add_argument("--verbose", action="store_true")
    args = parser.parse_args()
    # pymodbus logs every closed connection as an error; the tests close connections on purpose.
    # (pymodbus installs its own log format on import, so its logger's level is set directly.)
    logging.getLogger("pymodbus").setLevel(logging.DEBUG if args.verbose else logging.CRITICAL)

    with open(args.map, encoding="utf-8") as f:
        chamber_map = ChamberMap(json.load(f))
    store = ModbusSlaveContext(
        hr=ModbusSequentialDataBlock(0, initial_registers(chamber_map, args.initial)),
        ir=NoRegisters(),
        co=ModbusSequentialDataBlock(0, [False] * 8),  # digital outputs, as a power relay's coil
        di=NoRegisters(),
        zero_mode=True,  # addresses as on the wire (0-based), as imucal's maps give them
    )
    context = ModbusServerContext(slaves={chamber_map.slave_id: store}, single=False)
    controls = Controls(chamber_map, store)
    loop = asyncio.get_running_loop()

    if args.rtu:
        server_master, server_device = raw_pty()
        driver_master, driver_device = raw_pty()
        join_masters(loop, server_master, driver_master)
        server = ModbusSerialServer(
            context,
            framer=ModbusRtuFramer,
            handler=make_handler(ModbusSingleRequestHandler, controls, connected=False),
            port=os.ttyname(server_device),
            baudrate=115200,
        )
        await server.start()
        serving = asyncio.create_task(server.serve_forever())
        say({"rtu_device": os.ttyname(driver_device)})
    else:
        server = ModbusTcpServer(
            context,
            handler=make_handler(ModbusConnectedRequestHandler, controls, connected=True),
            address=("127.0.0.1", args.tcp_port),
            allow_reuse_address=True,
        )
        serving = asyncio.create_task(server.serve_forever())
        await server.serving
        say({"tcp_port": server.server.sockets[0].getsockname()[1]})

    follower = asyncio.create_task(follow_setpoint(controls))
    await serve_stdin(controls)
    follower.cancel()
    serving.cancel()
    await server.shutdown()


if __name__ == "__main__":
    asyncio.run(main())
