//! The recorder: logs every frame a node sends and receives as a `candump -L` file without ever
//! blocking the control path.
//!
//! Frames go into a bounded queue with [`Recorder::record`], which never blocks: if the queue is full
//! the frame is counted as dropped ([`RecorderStats::dropped`]) instead. A frame the candump format
//! cannot carry (CAN FD flag bits above 0x0F, see [`super`]) is not queued but counted as rejected
//! ([`RecorderStats::rejected`]); the first one is logged. A writer thread formats and writes the
//! lines through a buffered writer. The counters saturate at `u64::MAX`; [`Recorder::close`] logs
//! them when frames were lost.
//!
//! **Shutdown:** call [`Recorder::close`] (or at least [`Recorder::flush`]) before the process ends,
//! including on Ctrl-C: `select!` on `tokio::signal::ctrl_c()` in the main loop, send the neutral
//! command, then `close()` the recorder. Dropping the last clone also closes it, but
//! `std::process::exit` and an un-handled Ctrl-C skip destructors and lose the buffered tail.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use super::{Direction, TraceWriter, WriteError, check_frame};
use crate::frame::CanFrame;

/// Default queue length: about a minute of the full 100 Hz schedule.
pub const DEFAULT_CAPACITY: usize = 65_536;

/// Largest queue length [`Recorder::new`] accepts: the queue's slots are allocated up front
/// (a frame is about 80 bytes, so this is about 80 MiB).
pub const MAX_QUEUE_CAPACITY: usize = 1 << 20;

/// Recorder errors.
#[derive(Debug, thiserror::Error)]
pub enum RecorderError {
    /// Creating or writing the file failed.
    #[error("trace file I/O: {0}")]
    Io(#[from] io::Error),
    /// The recorder was already closed.
    #[error("recorder already closed")]
    Closed,
    /// The writer thread panicked.
    #[error("trace writer thread panicked")]
    WriterPanicked,
    /// A queue length of 0 or above [`MAX_QUEUE_CAPACITY`].
    #[error("trace queue capacity {requested} is not in 1..={MAX_QUEUE_CAPACITY}")]
    Capacity {
        /// The capacity asked for.
        requested: usize,
    },
}

/// Counts of a recorder.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RecorderStats {
    /// Frames handed to [`Recorder::record`] and queued.
    pub recorded: u64,
    /// Frames not queued because the queue was full or the recorder closed.
    pub dropped: u64,
    /// Frames not queued because the candump format cannot carry them (CAN FD flag bits above 0x0F).
    pub rejected: u64,
}

impl RecorderStats {
    /// Frames handed to the recorder that will not be in the file.
    pub fn lost(&self) -> u64 {
        self.dropped.saturating_add(self.rejected)
    }
}

/// Adds one to `counter`, saturating at `u64::MAX` (a wrapped loss counter would read as no loss).
fn bump(counter: &AtomicU64) -> u64 {
    let previous = counter
        .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| {
            Some(n.saturating_add(1))
        })
        // The closure always returns Some, so fetch_update cannot fail; both arms hold the old value.
        .unwrap_or_else(|n| n);
    previous.saturating_add(1)
}

enum Command {
    Frame {
        timestamp_ns: u64,
        direction: Direction,
        frame: CanFrame,
    },
    Flush(SyncSender<io::Result<()>>),
    Close,
}

struct Inner {
    tx: SyncSender<Command>,
    thread: Mutex<Option<JoinHandle<io::Result<()>>>>,
    recorded: AtomicU64,
    dropped: AtomicU64,
    rejected: AtomicU64,
}

impl Inner {
    fn close(&self) -> Result<RecorderStats, RecorderError> {
        let handle = self
            .thread
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        let Some(handle) = handle else {
            return Err(RecorderError::Closed);
        };
        // A blocking send: on shutdown waiting for the queue to drain is what we want.
        let _ = self.tx.send(Command::Close);
        handle.join().map_err(|_| RecorderError::WriterPanicked)??;
        Ok(self.stats())
    }

    fn stats(&self) -> RecorderStats {
        RecorderStats {
            recorded: self.recorded.load(Ordering::Relaxed),
            dropped: self.dropped.load(Ordering::Relaxed),
            rejected: self.rejected.load(Ordering::Relaxed),
        }
    }
}

impl Drop for Inner {
    fn drop(&mut self) {
        match self.close() {
            Ok(stats) if stats.lost() > 0 => log_losses(&stats),
            Ok(_) | Err(RecorderError::Closed) => {}
            Err(e) => tracing::warn!("closing trace recorder: {e}"),
        }
    }
}

fn log_losses(stats: &RecorderStats) {
    tracing::warn!(
        dropped = stats.dropped,
        rejected = stats.rejected,
        recorded = stats.recorded,
        "trace recorder lost frames"
    );
}

/// A handle to a trace recorder; clones share one file and queue.
#[derive(Clone)]
pub struct Recorder {
    inner: Arc<Inner>,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("stats", &self.inner.stats())
            .finish()
    }
}

impl Recorder {
    /// Creates (truncates) `path` and records to it with ` R`/` T` markers.
    ///
    /// # Errors
    /// [`RecorderError::Io`] if the file cannot be created.
    pub fn create(path: &Path, interface: &str) -> Result<Self, RecorderError> {
        let file = File::create(path)?;
        Self::new(Box::new(file), interface, true, DEFAULT_CAPACITY)
    }

    /// Records to the end of `path` (created if missing) with ` R`/` T` markers: a resumed session
    /// goes on in its trace.
    ///
    /// # Errors
    /// [`RecorderError::Io`] if the file cannot be opened.
    pub fn append(path: &Path, interface: &str) -> Result<Self, RecorderError> {
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)?;
        Self::new(Box::new(file), interface, true, DEFAULT_CAPACITY)
    }

    /// Records to any writer. `markers` adds ` R`/` T` to each line; `capacity` bounds the queue.
    ///
    /// # Errors
    /// [`RecorderError::Capacity`] for a capacity of 0 or above [`MAX_QUEUE_CAPACITY`],
    /// [`RecorderError::Io`] if the writer thread cannot be started.
    pub fn new(
        out: Box<dyn Write + Send>,
        interface: &str,
        markers: bool,
        capacity: usize,
    ) -> Result<Self, RecorderError> {
        if !(1..=MAX_QUEUE_CAPACITY).contains(&capacity) {
            return Err(RecorderError::Capacity {
                requested: capacity,
            });
        }
        let (tx, rx) = mpsc::sync_channel::<Command>(capacity);
        let mut writer = TraceWriter::new(BufWriter::new(out), interface, markers);
        let thread = std::thread::Builder::new()
            .name("can-trace".into())
            .spawn(move || {
                let mut result = Ok(());
                for cmd in rx {
                    match cmd {
                        Command::Frame {
                            timestamp_ns,
                            direction,
                            frame,
                        } => {
                            if result.is_ok() {
                                match writer.write(timestamp_ns, &frame, direction) {
                                    Ok(()) => {}
                                    Err(WriteError::Io(e)) => result = Err(e),
                                    // `record` refuses (and counts) these before they are queued.
                                    Err(e @ WriteError::Unrepresentable(_)) => {
                                        tracing::debug!(%e, "trace frame not written");
                                    }
                                }
                            }
                        }
                        Command::Flush(ack) => {
                            let flushed = match &result {
                                Ok(()) => writer.flush(),
                                Err(e) => Err(io::Error::new(e.kind(), e.to_string())),
                            };
                            let _ = ack.send(flushed);
                        }
                        Command::Close => break,
                    }
                }
                result.and_then(|()| writer.flush())
            })?;
        Ok(Self {
            inner: Arc::new(Inner {
                tx,
                thread: Mutex::new(Some(thread)),
                recorded: AtomicU64::new(0),
                dropped: AtomicU64::new(0),
                rejected: AtomicU64::new(0),
            }),
        })
    }

    /// Queues a frame. Never blocks: a full queue (or a closed recorder) counts the frame as dropped,
    /// a frame without a candump form as rejected.
    pub fn record(&self, timestamp_ns: u64, direction: Direction, frame: &CanFrame) {
        if let Err(e) = check_frame(frame) {
            if bump(&self.inner.rejected) == 1 {
                tracing::warn!(%e, ?frame, "trace recorder rejects a frame (further ones only counted)");
            }
            return;
        }
        let cmd = Command::Frame {
            timestamp_ns,
            direction,
            frame: *frame,
        };
        match self.inner.tx.try_send(cmd) {
            Ok(()) => {
                bump(&self.inner.recorded);
            }
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                bump(&self.inner.dropped);
            }
        }
    }

    /// Waits until every frame queued so far is written and flushed to the file.
    ///
    /// # Errors
    /// [`RecorderError::Io`] for a write error, [`RecorderError::Closed`] after `close`.
    pub fn flush(&self) -> Result<(), RecorderError> {
        let (ack_tx, ack_rx) = mpsc::sync_channel(1);
        self.inner
            .tx
            .send(Command::Flush(ack_tx))
            .map_err(|_| RecorderError::Closed)?;
        ack_rx.recv().map_err(|_| RecorderError::Closed)??;
        Ok(())
    }

    /// Writes everything queued, flushes, stops the writer thread and returns the counts. Later
    /// `record` calls count as dropped.
    ///
    /// # Errors
    /// [`RecorderError::Io`] for a write error, [`RecorderError::Closed`] if already closed.
    pub fn close(&self) -> Result<RecorderStats, RecorderError> {
        let stats = self.inner.close()?;
        if stats.lost() > 0 {
            log_losses(&stats);
        }
        Ok(stats)
    }

    /// Counts so far.
    pub fn stats(&self) -> RecorderStats {
        self.inner.stats()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::{ReadMode, TraceReader};

    /// A writer that blocks until released, to fill the queue deterministically.
    struct Gate(Arc<(Mutex<bool>, std::sync::Condvar)>, Arc<Mutex<Vec<u8>>>);

    impl Write for Gate {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            let (lock, cv) = &*self.0;
            let mut open = lock.lock().unwrap();
            while !*open {
                open = cv.wait(open).unwrap();
            }
            self.1.lock().unwrap().extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    fn frame(n: u8) -> CanFrame {
        CanFrame::new_extended(0x0CFF_5080, &[n; 8]).unwrap()
    }

    #[test]
    fn records_to_a_file_and_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.log");
        let rec = Recorder::create(&path, "vcan0").unwrap();
        for n in 0..100u8 {
            rec.record(u64::from(n) * 10_000_000, Direction::Transmit, &frame(n));
        }
        rec.flush().unwrap();
        let stats = rec.close().unwrap();
        assert_eq!(
            stats,
            RecorderStats {
                recorded: 100,
                dropped: 0,
                rejected: 0,
            }
        );
        let file = std::io::BufReader::new(File::open(&path).unwrap());
        let recs: Vec<_> = TraceReader::new(file, ReadMode::Stop)
            .map(|r| r.unwrap())
            .collect();
        assert_eq!(recs.len(), 100);
        assert_eq!(recs[99].frame, frame(99));
        assert_eq!(recs[99].direction, Some(Direction::Transmit));
        assert!(matches!(rec.close(), Err(RecorderError::Closed)));
    }

    #[test]
    fn full_queue_counts_overflow_without_blocking() {
        let gate = Arc::new((Mutex::new(false), std::sync::Condvar::new()));
        let sink = Arc::new(Mutex::new(Vec::new()));
        // The BufWriter holds 8 KiB before it writes, so use lines big enough to reach the gate soon.
        let rec = Recorder::new(
            Box::new(Gate(gate.clone(), sink.clone())),
            "vcan0",
            false,
            4,
        )
        .unwrap();
        for n in 0..1000u32 {
            rec.record(u64::from(n), Direction::Receive, &frame(n as u8));
        }
        let stats = rec.stats();
        assert!(stats.dropped > 0, "{stats:?}");
        assert_eq!(stats.recorded + stats.dropped, 1000);
        *gate.0.lock().unwrap() = true;
        gate.1.notify_all();
        let closed = rec.close().unwrap();
        let lines = String::from_utf8(sink.lock().unwrap().clone())
            .unwrap()
            .lines()
            .count() as u64;
        assert_eq!(lines, closed.recorded);
    }

    #[test]
    fn frames_without_a_candump_form_are_rejected_and_counted() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fd.log");
        let rec = Recorder::create(&path, "can0").unwrap();
        let id = crate::frame::CanId::Standard(0x123);
        let ok = CanFrame::new_fd(id, &[1; 12], 0x0F).unwrap();
        let wide = CanFrame::new_fd(id, &[1; 12], 0x10).unwrap();
        rec.record(1_000, Direction::Receive, &ok);
        rec.record(2_000, Direction::Receive, &wide);
        rec.record(3_000, Direction::Receive, &wide);
        let stats = rec.close().unwrap();
        assert_eq!(
            stats,
            RecorderStats {
                recorded: 1,
                dropped: 0,
                rejected: 2,
            }
        );
        assert_eq!(stats.lost(), 2);
        let file = std::io::BufReader::new(File::open(&path).unwrap());
        let recs: Vec<_> = TraceReader::new(file, ReadMode::Stop)
            .map(|r| r.unwrap())
            .collect();
        assert_eq!(recs.len(), 1);
        assert_eq!(recs[0].frame, ok);
    }

    #[test]
    fn queue_capacity_is_bounded() {
        for capacity in [0, MAX_QUEUE_CAPACITY + 1, usize::MAX] {
            assert!(matches!(
                Recorder::new(Box::new(io::sink()), "can0", false, capacity),
                Err(RecorderError::Capacity { requested }) if requested == capacity
            ));
        }
    }

    #[test]
    fn counters_saturate() {
        let counter = AtomicU64::new(u64::MAX - 1);
        assert_eq!(bump(&counter), u64::MAX);
        assert_eq!(bump(&counter), u64::MAX);
        assert_eq!(counter.load(Ordering::Relaxed), u64::MAX);
    }
}
