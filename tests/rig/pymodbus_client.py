#!/usr/bin/python3
"""Independent Modbus peer for facedyn's simulated drive: a pymodbus client (TCP, or RTU with
--rtu DEVICE at 19200 8N1).

It follows the register map given on the command line (the test passes sim.yaml's values):
writes the setpoint and the run word, then samples the output-frequency register for
--seconds and prints one JSON object: {"samples_hz": [...], "status": N}.

usage: pymodbus_client.py [--rtu DEVICE] --port P --setpoint-register R --counts-per-hz C --hz F
                          --command-register R --run-value V --output-register R
                          --status-register R [--seconds S]
"""
import argparse
import json
import sys
import time

from pymodbus.client import ModbusSerialClient, ModbusTcpClient


def main():
    parser = argparse.ArgumentParser()
    for name in ("port", "setpoint-register", "command-register", "run-value",
                 "output-register", "status-register"):
        parser.add_argument("--" + name, type=lambda text: int(text, 0), required=True)
    parser.add_argument("--counts-per-hz", type=float, required=True)
    parser.add_argument("--hz", type=float, required=True)
    parser.add_argument("--seconds", type=float, default=1.0)
    parser.add_argument("--unit", type=int, default=1)
    parser.add_argument("--rtu", default="")
    args = parser.parse_args()

    if args.rtu:
        client = ModbusSerialClient(port=args.rtu, baudrate=19200, bytesize=8, parity="N",
                                    stopbits=1, timeout=1)
    else:
        client = ModbusTcpClient("127.0.0.1", port=args.port, timeout=2)
    if not client.connect():
        print("cannot connect", file=sys.stderr)
        return 1
    counts = int(round(args.hz * args.counts_per_hz))
    for address, value in ((args.setpoint_register, counts),
                           (args.command_register, args.run_value)):
        reply = client.write_register(address, value, slave=args.unit)
        if reply.isError():
            print(f"write {address} failed: {reply}", file=sys.stderr)
            return 1
    samples = []
    end = time.monotonic() + args.seconds
    while time.monotonic() < end:
        reply = client.read_holding_registers(args.output_register, 1, slave=args.unit)
        if reply.isError():
            print(f"read {args.output_register} failed: {reply}", file=sys.stderr)
            return 1
        samples.append(reply.registers[0] / args.counts_per_hz)
        time.sleep(0.05)
    status = client.read_holding_registers(args.status_register, 1, slave=args.unit)
    if status.isError():
        print(f"read {args.status_register} failed: {status}", file=sys.stderr)
        return 1
    print(json.dumps({"samples_hz": samples, "status": status.registers[0]}))
    client.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
