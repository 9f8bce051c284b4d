//! The model's bus side: what the controller offers to the bus and what the bus does to it — a
//! frame sent, lost or aborted, a frame received through the filters, the error counters — and the
//! interrupt lines that follow.

use super::super::bit;
use super::{Model, IER_FFIE0, MCR_RFLM, TSR_ALST, TSR_TERR};

/// A frame a transmit mailbox holds for the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TxRequest {
    /// The identifier: 11 bits, or 29 with `extended`.
    pub id: u32,
    /// IDE: an extended identifier.
    pub extended: bool,
    /// RTR: a remote frame.
    pub remote: bool,
    /// The data length code (0–15; 9–15 mean 8 bytes).
    pub dlc: u8,
    /// The data bytes (as many as the length code says are sent).
    pub data: [u8; 8],
    /// ABRQ: software asked for the transmission to be aborted.
    pub abort_requested: bool,
}

impl TxRequest {
    /// The data bytes the frame carries.
    pub fn payload(&self) -> &[u8] {
        &self.data[..usize::from(self.dlc.min(8))]
    }
}

/// A frame arriving from the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RxRequest {
    /// The identifier: 11 bits, or 29 with `extended`.
    pub id: u32,
    /// IDE.
    pub extended: bool,
    /// RTR.
    pub remote: bool,
    /// The data length code as received (0–15).
    pub dlc: u8,
    /// The data bytes.
    pub data: [u8; 8],
}

impl RxRequest {
    /// A standard data frame.
    pub fn standard(id: u16, dlc: u8, data: [u8; 8]) -> Self {
        Self {
            id: u32::from(id & 0x7FF),
            extended: false,
            remote: false,
            dlc: dlc.min(15),
            data,
        }
    }

    /// The frame's identifier register as the FIFO and the filters see it (RIxR without its
    /// reserved bit 0).
    fn rir(&self) -> u32 {
        let id = if self.extended {
            (self.id & 0x1FFF_FFFF) << 3
        } else {
            (self.id & 0x7FF) << 21
        };
        id | if self.extended { bit::RIR_IDE } else { 0 }
            | if self.remote { bit::RIR_RTR } else { 0 }
    }
}

/// What became of a frame from the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reception {
    /// It is in FIFO 0.
    Stored,
    /// FIFO 0 was full: FOVR is set and a frame was lost (the newest stored one or this one, as
    /// RFLM says).
    Overrun,
    /// No filter passed it to FIFO 0 (or the controller is not on the bus): the software never sees
    /// it.
    Filtered,
}

/// Why a transmission did not complete.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Failure {
    /// Another node's frame won the arbitration (ALST).
    ArbitrationLost,
    /// A bus error ended it (TERR).
    Error,
}

impl Model {
    /// The mailbox the controller offers to the next arbitration: the pending one of the lowest
    /// identifier (ties: the lower number), or the oldest request with TXFP set. `None` if none is
    /// pending or the controller is not on the bus.
    pub fn offered(&self) -> Option<usize> {
        if !self.on_bus() {
            return None;
        }
        let mut first: Option<(u32, usize)> = None;
        for (i, m) in self.tx.iter().enumerate() {
            let key = self.priority(m);
            if m.pending() && first.is_none_or(|(k, _)| key < k) {
                first = Some((key, i));
            }
        }
        first.map(|(_, i)| i)
    }

    /// The frame mailbox `i` holds for the bus, if it is pending.
    pub fn request(&self, i: usize) -> Option<TxRequest> {
        let m = self.tx.get(i).filter(|m| m.pending())?;
        let extended = m.tir & bit::RIR_IDE != 0;
        let mut data = [0u8; 8];
        data[..4].copy_from_slice(&m.tdlr.to_le_bytes());
        data[4..].copy_from_slice(&m.tdhr.to_le_bytes());
        Some(TxRequest {
            id: if extended { m.tir >> 3 } else { m.tir >> 21 },
            extended,
            remote: m.tir & bit::RIR_RTR != 0,
            dlc: (m.tdtr & 0xF) as u8,
            data,
            abort_requested: m.status & bit::abrq(0) != 0,
        })
    }

    /// Mailbox `i`'s frame was acknowledged on the bus: RQCP and TXOK set, the mailbox empty.
    /// `false` (and nothing changes) if it was not pending.
    pub fn transmitted(&mut self, i: usize) -> bool {
        self.complete(i, bit::rqcp(0) | bit::txok(0))
    }

    /// Mailbox `i`'s transmission did not complete. With automatic retransmission (NART clear) and
    /// no abort requested the mailbox stays pending for the next arbitration, with ALST or TERR
    /// set; otherwise it ends there (RQCP set, TXOK clear). `false` if it was not pending.
    pub fn failed(&mut self, i: usize, why: Failure) -> bool {
        let flag = match why {
            Failure::ArbitrationLost => TSR_ALST,
            Failure::Error => TSR_TERR,
        };
        let retry = self.mcr & bit::MCR_NART == 0;
        let Some(m) = self.tx.get_mut(i).filter(|m| m.pending()) else {
            return false;
        };
        if retry && m.status & bit::abrq(0) == 0 {
            m.status |= flag;
            return true;
        }
        self.complete(i, bit::rqcp(0) | flag)
    }

    /// The controller honours mailbox `i`'s abort request while its frame is not on the bus: RQCP
    /// set, TXOK clear, the mailbox empty. `false` (and nothing changes) if no abort was requested.
    pub fn abort(&mut self, i: usize) -> bool {
        let requested = self
            .tx
            .get(i)
            .is_some_and(|m| m.pending() && m.status & bit::abrq(0) != 0);
        requested && self.complete(i, bit::rqcp(0))
    }

    fn complete(&mut self, i: usize, flags: u32) -> bool {
        let Some(m) = self.tx.get_mut(i).filter(|m| m.pending()) else {
            return false;
        };
        m.tir &= !bit::TIR_TXRQ;
        m.status = (m.status & (TSR_ALST | TSR_TERR)) | flags;
        true
    }

    /// A frame from the bus, through filter bank 0 into FIFO 0.
    pub fn receive(&mut self, frame: &RxRequest) -> Reception {
        if !self.on_bus() || !self.passes_filters(frame.rir()) {
            return Reception::Filtered;
        }
        self.store(frame)
    }

    /// A frame straight into FIFO 0, as if the filters were open: what a single-board QEMU run's
    /// stimulus is (the frames that reached the FIFO).
    pub fn store(&mut self, frame: &RxRequest) -> Reception {
        let entry = [
            frame.rir(),
            // FMI 0 (filter bank 0's one filter), no time stamp.
            u32::from(frame.dlc & 0xF),
            u32::from_le_bytes([frame.data[0], frame.data[1], frame.data[2], frame.data[3]]),
            u32::from_le_bytes([frame.data[4], frame.data[5], frame.data[6], frame.data[7]]),
        ];
        if usize::from(self.fifo_len) == self.fifo.len() {
            self.fifo_overrun = true;
            if self.mcr & MCR_RFLM == 0 {
                if let Some(newest) = self.fifo.last_mut() {
                    *newest = entry;
                }
            }
            return Reception::Overrun;
        }
        if let Some(slot) = self.fifo.get_mut(usize::from(self.fifo_len)) {
            *slot = entry;
        }
        self.fifo_len += 1;
        if usize::from(self.fifo_len) == self.fifo.len() {
            self.fifo_full = true;
        }
        Reception::Stored
    }

    /// Whether filter bank 0 passes a frame with identifier register `rir` into FIFO 0 (the model
    /// holds no other bank; a frame no active filter passes is dropped, as on the chip).
    fn passes_filters(&self, rir: u32) -> bool {
        let active = self.fa1r & 1 != 0 && !self.filter_init();
        let fifo0 = self.ffa1r & 1 == 0;
        let scale32 = self.fs1r & 1 != 0;
        if !(active && fifo0 && scale32) {
            return false;
        }
        let [r1, r2] = self.bank0;
        if self.fm1r & 1 == 0 {
            (rir ^ r1) & r2 & !1 == 0
        } else {
            rir == r1 & !1 || rir == r2 & !1
        }
    }

    /// The bus side's error counters: the warning, passive and bus-off flags follow from them
    /// (bus-off until `bus_off` is cleared: the recovery sequence is the bus's). A change of state
    /// sets ERRI where IER enables it.
    pub fn set_error_counters(&mut self, tec: u8, rec: u8, bus_off: bool) {
        let before = self.esr() & (bit::ESR_EWGF | bit::ESR_EPVF | bit::ESR_BOFF);
        (self.tec, self.rec, self.bus_off) = (tec, rec, bus_off);
        let now = self.esr() & (bit::ESR_EWGF | bit::ESR_EPVF | bit::ESR_BOFF);
        let enabled = [
            (bit::ESR_EWGF, bit::IER_EWGIE),
            (bit::ESR_EPVF, bit::IER_EPVIE),
            (bit::ESR_BOFF, bit::IER_BOFIE),
        ]
        .iter()
        .any(|&(flag, enable)| (before ^ now) & flag != 0 && self.ier & enable != 0);
        if enabled && self.ier & bit::IER_ERRIE != 0 {
            self.msr |= bit::MSR_ERRI;
        }
    }

    /// The transmit interrupt's line: a completed mailbox (RQCP) with TMEIE set.
    pub fn tx_interrupt(&self) -> bool {
        self.ier & bit::IER_TMEIE != 0 && self.tx.iter().any(|m| m.status & bit::rqcp(0) != 0)
    }

    /// FIFO 0's interrupt line: a message pending (FMPIE0), the FIFO full (FFIE0) or overrun
    /// (FOVIE0).
    pub fn rx0_interrupt(&self) -> bool {
        (self.ier & bit::IER_FMPIE0 != 0 && self.fifo_len > 0)
            || (self.ier & IER_FFIE0 != 0 && self.fifo_full)
            || (self.ier & bit::IER_FOVIE0 != 0 && self.fifo_overrun)
    }

    /// The status-change interrupt's line: ERRI.
    pub fn sce_interrupt(&self) -> bool {
        self.msr & bit::MSR_ERRI != 0
    }
}
