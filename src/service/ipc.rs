//! The services' wiring to the iceoryx2 transport: opening a run's ports and
//! adapting them to the [`ports`](super::ports) traits.

use crate::sample::FrameSample;
use crate::service::ports::{FrameSink, FrameSource, PortError};
use crate::transport::{FramePublisher, FrameSendError, FrameSubscriber, IpcConfig, IpcNode, Role, RunId};
use anyhow::{Context, Result};

/// Opens this process's node in run `run_id`.
pub fn open_node(run_id: &str, role: Role) -> Result<IpcNode> {
    let run = RunId::new(run_id).with_context(|| format!("run id `{run_id}`"))?;
    let node = IpcNode::open(&IpcConfig::new(run), role).with_context(|| format!("opening the {role} node of run `{run_id}`"))?;
    Ok(node)
}

/// Removes what killed processes of earlier runs left on this host; returns
/// how many dead nodes were removed.
pub fn cleanup_stale() -> Result<usize> {
    let reports = crate::transport::cleanup_dead_runs(|_| true).context("cleaning up after earlier runs")?;
    Ok(reports.iter().map(|(_, r)| r.removed.len()).sum())
}

impl FrameSource for FrameSubscriber {
    #[inline]
    fn try_recv(&mut self, out: &mut FrameSample) -> Result<bool, PortError> {
        match FrameSubscriber::try_recv(self) {
            Ok(Some(s)) => {
                *out = s;
                Ok(true)
            }
            Ok(None) => Ok(false),
            Err(e) => Err(PortError { port: format!("netfi/{}/{}", self.run_id(), self.channel()), message: e.to_string() }),
        }
    }

    fn peers(&mut self) -> Option<usize> {
        Some(self.peers_connected())
    }
}

impl FrameSink for FramePublisher {
    #[inline]
    fn send_with(&mut self, sample: &FrameSample, stamp: impl FnOnce(&mut FrameSample)) -> Result<Option<usize>, PortError> {
        FramePublisher::send_from(self, sample, stamp)
        .map(Some)
        .map_err(|e: FrameSendError| PortError { port: format!("netfi/{}/{}", self.run_id(), self.channel()), message: e.to_string() })
    }

    fn peers(&mut self) -> Option<usize> {
        Some(self.peers_connected())
    }
}

