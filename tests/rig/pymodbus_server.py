#!/usr/bin/python3
"""Independent Modbus TCP peer for facedyn's rig tests: a pymodbus server.

It holds a block of holding registers (addresses 0..size-1 exactly as sent on the wire) and
appends every write to a log file as "<address> <value>" lines, so a test can check which
registers facedyn's DriveClient wrote, in which order, without trusting facedyn's own reader.
It binds 127.0.0.1 on a free port and writes that port to --ready once it is listening.

usage: pymodbus_server.py --ready FILE --log FILE [--size N] [--preset ADDR=VALUE ...]
"""
import argparse
import asyncio
import os
import sys

from pymodbus.datastore import (ModbusSequentialDataBlock, ModbusServerContext,
                                ModbusSlaveContext)
from pymodbus.server import StartAsyncTcpServer


class LoggingBlock(ModbusSequentialDataBlock):
    """A register block that records writes; reads behave as usual."""

    def __init__(self, size, log_path):
        super().__init__(0, [0] * size)
        self.log_path = log_path

    def setValues(self, address, values):  # pylint: disable=invalid-name
        super().setValues(address, values)
        if not isinstance(values, list):
            values = [values]
        with open(self.log_path, "a", encoding="ascii") as log:
            for offset, value in enumerate(values):
                log.write(f"{address + offset} {value}\n")


async def serve(args):
    block = LoggingBlock(args.size, args.log)
    for preset in args.preset:
        address, value = preset.split("=")
        # Presets go straight into the store so they do not appear in the write log.
        ModbusSequentialDataBlock.setValues(block, int(address, 0), [int(value, 0)])
    slave = ModbusSlaveContext(hr=block, zero_mode=True)
    context = ModbusServerContext(slaves=slave, single=True)
    server = await StartAsyncTcpServer(context=context, address=("127.0.0.1", 0),
                                       defer_start=True)
    task = asyncio.create_task(server.serve_forever())
    while server.server is None:
        await asyncio.sleep(0.01)
    port = server.server.sockets[0].getsockname()[1]
    tmp = args.ready + ".tmp"
    with open(tmp, "w", encoding="ascii") as ready:
        ready.write(f"{port}\n")
    os.rename(tmp, args.ready)  # the test sees the whole line or nothing
    await task


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--ready", required=True)
    parser.add_argument("--log", required=True)
    parser.add_argument("--size", type=int, default=0x2200)
    parser.add_argument("--preset", action="append", default=[])
    asyncio.run(serve(parser.parse_args()))


if __name__ == "__main__":
    main()
