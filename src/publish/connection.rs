//! The MQTT connection's thread: rumqttc's event loop on a runtime of its own, reconnecting
//! every second; on each connection the outbox's births (or `online`) and then its held
//! messages, forwarded in batches between which the connection gets to send them.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use rumqttc::EventLoop;

use super::outbox::{Forward, Outbox, lock};
use super::spool::Spool;

/// Forwards held records while connected, a batch at a time, each batch under the outbox's lock
/// (so a Sparkplug sequence number is handed to the connection in the order it was counted).
async fn forwarder(outbox: Arc<Mutex<Outbox>>, connected: Arc<AtomicBool>) {
    loop {
        let turn = if connected.load(Ordering::SeqCst) {
            let mut ob = lock(&outbox);
            ob.subscribe_commands();
            ob.forward_some()
        } else {
            Forward::Idle
        };
        match turn {
            // The connection's task runs between two batches (one runtime thread for both).
            Forward::More => tokio::task::yield_now().await,
            Forward::Full => tokio::time::sleep(Duration::from_millis(5)).await,
            Forward::Idle => tokio::time::sleep(Duration::from_millis(50)).await,
        }
    }
}

/// Runs the connection until the client disconnects; `connected` mirrors its state.
pub async fn run(mut eventloop: EventLoop, outbox: Arc<Mutex<Outbox>>, connected: Arc<AtomicBool>, broker: String) {
    let forwarding = tokio::spawn(forwarder(Arc::clone(&outbox), Arc::clone(&connected)));
    let mut said_down = false;
    loop {
        match eventloop.poll().await {
            Ok(rumqttc::Event::Incoming(rumqttc::Packet::ConnAck(_))) => {
                connected.store(true, Ordering::SeqCst);
                eprintln!("mbtap: mqtt: connected to {broker}");
                said_down = false;
                let mut ob = lock(&outbox);
                ob.connected();
                if ob.holding() {
                    let on_disk = ob.spool.as_ref().map_or(0, Spool::bytes);
                    let in_memory = ob.memory.len();
                    eprintln!(
                        "mbtap: mqtt: forwarding what was held while the broker was away ({on_disk} bytes on disk, {in_memory} updates in memory; historical data in Sparkplug)"
                    );
                }
            }
            Ok(rumqttc::Event::Incoming(rumqttc::Packet::Publish(p))) => {
                lock(&outbox).incoming(&p.topic, &p.payload, p.retain);
            }
            Ok(rumqttc::Event::Outgoing(rumqttc::Outgoing::Disconnect)) => {
                // The DISCONNECT may still sit in the write buffer behind the last
                // publications: poll on until the broker closes (bounded).
                let drain = async { while eventloop.poll().await.is_ok() {} };
                let _ = tokio::time::timeout(Duration::from_secs(1), drain).await;
                break;
            }
            Ok(_) => {}
            Err(e) => {
                if connected.swap(false, Ordering::SeqCst) || !said_down {
                    eprintln!("mbtap: mqtt: {broker}: {e}; analysis goes on, retrying every second");
                    said_down = true;
                }
                if matches!(e, rumqttc::ConnectionError::RequestsDone) {
                    break;
                }
                let will = {
                    let mut ob = lock(&outbox);
                    if let rumqttc::ConnectionError::MqttState(rumqttc::StateError::Deserialization(
                        rumqttc::mqttbytes::Error::PayloadSizeLimitExceeded(bytes),
                    )) = &e
                    {
                        ob.oversized_message(*bytes, super::outbox::MAX_INCOMING);
                    }
                    ob.disconnected();
                    ob.will()
                };
                // The next session's will carries the next bdSeq (Sparkplug 3.0 §7.2).
                if let Some(w) = will {
                    eventloop.mqtt_options.set_last_will(w);
                }
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    }
    forwarding.abort();
}
