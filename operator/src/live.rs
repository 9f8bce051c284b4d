//! `amiro monitor --foxglove`: the bus served live over Foxglove's WebSocket protocol (the `foxglove` SDK's server),
//! with the same channels, schemas and messages as an MCAP recording (`record`), so a Foxglove layout made for a
//! recording works live and the other way round. Every channel is advertised at the start, so a client sees every
//! topic before its first sample; each message carries its frame's time as its log time.

use std::collections::HashMap;
use std::sync::Arc;

use amiro_can::TOPICS;
use anyhow::{anyhow, Context as _, Result};
use foxglove::{ChannelBuilder, Context, PartialMetadata, RawChannel, Schema, WebSocketServer};

use crate::frame::{LoggedFrame, Timestamp};
use crate::record::{command_spec, frames_spec, messages, time_ns, topic_spec, ChannelSpec};

/// Where the server listens unless told: Foxglove's default.
pub const DEFAULT_ADDRESS: &str = "127.0.0.1:8765";

/// A running server and its channels.
pub struct LiveServer {
    context: Arc<Context>,
    server: Option<foxglove::WebSocketServerHandle>,
    channels: HashMap<String, Arc<RawChannel>>,
    port: u16,
}

impl LiveServer {
    /// Starts serving on `address` (`HOST:PORT`; port 0 picks a free one).
    pub fn start(address: &str) -> Result<Self> {
        let (host, port) = address
            .rsplit_once(':')
            .and_then(|(host, port)| Some((host, port.parse::<u16>().ok()?)))
            .ok_or_else(|| {
                anyhow!("--foxglove {address:?}: write HOST:PORT, e.g. {DEFAULT_ADDRESS}")
            })?;
        let context = Context::new();
        let server = WebSocketServer::new()
            .name(format!("amiro {}", env!("CARGO_PKG_VERSION")))
            .context(&context)
            .bind(host, port)
            .start_blocking()
            .map_err(|error| anyhow!("cannot serve Foxglove on {address}: {error}"))?;
        let port = server.port();
        let mut live = Self {
            context,
            server: Some(server),
            channels: HashMap::new(),
            port,
        };
        live.channel(&frames_spec())?;
        for info in TOPICS {
            if info.is_sensor {
                live.channel(&topic_spec(info.topic))?;
            }
            live.channel(&command_spec(info.topic))?;
        }
        Ok(live)
    }

    /// The port it listens on.
    pub fn port(&self) -> u16 {
        self.port
    }

    fn channel(&mut self, spec: &ChannelSpec) -> Result<Arc<RawChannel>> {
        if let Some(channel) = self.channels.get(&spec.name) {
            return Ok(channel.clone());
        }
        let channel = ChannelBuilder::new(spec.name.clone())
            .context(&self.context)
            .message_encoding("json")
            .schema(Schema::new(
                spec.schema_name.clone(),
                "jsonschema",
                spec.schema.to_string().into_bytes(),
            ))
            .metadata(spec.metadata.clone())
            .build_raw()
            .map_err(|error| anyhow!("cannot open the channel {}: {error}", spec.name))
            .context("serving Foxglove")?;
        self.channels.insert(spec.name.clone(), channel.clone());
        Ok(channel)
    }

    /// Sends one frame to the connected clients: on `/amiro/frames` and decoded on its topic's channel.
    pub fn frame(&mut self, logged: &LoggedFrame) -> Result<()> {
        let time = time_ns(logged.timestamp.unwrap_or_else(Timestamp::now));
        let meta = PartialMetadata {
            log_time: Some(time),
        };
        let (record, decoded) = messages(logged);
        self.channel(&frames_spec())?
            .log_with_meta(record.to_string().as_bytes(), meta);
        if let Some((spec, body)) = decoded {
            self.channel(&spec)?
                .log_with_meta(body.to_string().as_bytes(), meta);
        }
        Ok(())
    }
}

impl Drop for LiveServer {
    fn drop(&mut self) {
        if let Some(server) = self.server.take() {
            // The clients' queues are sent by the server's own tasks: give the last messages a moment to leave.
            std::thread::sleep(std::time::Duration::from_millis(200));
            server.stop().wait_blocking();
        }
    }
}
