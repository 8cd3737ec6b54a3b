"""The pymodbus server context of the interop servers: holding registers from `values` at
protocol address `first` for the given units. The per-device context was renamed across pymodbus
3.x (ModbusSlaveContext -> ModbusDeviceContext, slaves= -> devices=): both are tried."""
import pymodbus.datastore as ds


def server_context(first, values, units=(1,)):
    Device = getattr(ds, "ModbusDeviceContext", None) or getattr(ds, "ModbusSlaveContext")
    # Block address first + 1 holds protocol address `first` (the device context adds 1, as
    # Modbus numbering does).
    def device():
        block = ds.ModbusSequentialDataBlock(first + 1, list(values))
        try:
            return Device(hr=block)
        except TypeError:
            return Device(di=None, co=None, hr=block, ir=None)

    devices = {u: device() for u in units}
    try:
        return ds.ModbusServerContext(devices=devices, single=False)
    except TypeError:
        return ds.ModbusServerContext(slaves=devices, single=False)
