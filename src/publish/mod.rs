//! What the sniffer hears, served to others: a read-only Modbus TCP server of the register
//! image (spy mode) and MQTT.
