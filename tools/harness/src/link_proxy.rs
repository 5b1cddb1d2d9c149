//! A TCP proxy between the two ends of a bridge, which cuts the link on demand and restores
//! it: what a pulled cable or a dead switch does to `agp bridge`, on the loopback.
//!
//! The connecting end is given the proxy's port; the proxy forwards each connection to the
//! listening end, byte for byte (TLS passes through untouched). [`LinkProxy::cut`] closes
//! every connection under way and, until [`LinkProxy::restore`], closes each new one as soon
//! as it is accepted, so the connecting end's retries fail as they would on a dead link.

use std::io::{Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

/// How often the accepting thread looks whether it should stop.
const ACCEPT_POLL: Duration = Duration::from_millis(5);

struct Inner {
    up: AtomicBool,
    stop: AtomicBool,
    /// The two sockets of every connection under way (for a cut to close them).
    open: Mutex<Vec<TcpStream>>,
    connections: AtomicU64,
    refused: AtomicU64,
}

/// A proxy on `127.0.0.1:port()` to a bridge's listening end.
pub struct LinkProxy {
    port: u16,
    inner: Arc<Inner>,
    accept: Option<JoinHandle<()>>,
}

impl LinkProxy {
    /// Listens on a free port of the loopback, forwarding to `target`.
    pub fn start(target: SocketAddr) -> std::io::Result<Self> {
        let listener = TcpListener::bind("127.0.0.1:0")?;
        listener.set_nonblocking(true)?;
        let port = listener.local_addr()?.port();
        let inner = Arc::new(Inner {
            up: AtomicBool::new(true),
            stop: AtomicBool::new(false),
            open: Mutex::new(Vec::new()),
            connections: AtomicU64::new(0),
            refused: AtomicU64::new(0),
        });
        let accept = {
            let inner = Arc::clone(&inner);
            std::thread::Builder::new()
                .name("link-proxy".into())
                .spawn(move || accept_loop(&listener, target, &inner))?
        };
        Ok(Self {
            port,
            inner,
            accept: Some(accept),
        })
    }

    /// The port the connecting end is given.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// Cuts the link: every connection under way is closed, and new ones are closed as soon
    /// as they are accepted, until [`Self::restore`].
    pub fn cut(&self) {
        self.inner.up.store(false, Ordering::SeqCst);
        close_all(&self.inner);
    }

    /// Lets connections through again.
    pub fn restore(&self) {
        self.inner.up.store(true, Ordering::SeqCst);
    }

    /// Whether the link is up (not cut).
    pub fn is_up(&self) -> bool {
        self.inner.up.load(Ordering::SeqCst)
    }

    /// Connections forwarded so far, and connections closed at once during a cut.
    pub fn counts(&self) -> (u64, u64) {
        (
            self.inner.connections.load(Ordering::Relaxed),
            self.inner.refused.load(Ordering::Relaxed),
        )
    }
}

impl Drop for LinkProxy {
    fn drop(&mut self) {
        self.inner.stop.store(true, Ordering::SeqCst);
        close_all(&self.inner);
        if let Some(a) = self.accept.take() {
            let _ = a.join();
        }
    }
}

fn close_all(inner: &Inner) {
    let mut open = inner.open.lock().unwrap_or_else(|e| e.into_inner());
    for s in open.drain(..) {
        let _ = s.shutdown(Shutdown::Both);
    }
}

fn accept_loop(listener: &TcpListener, target: SocketAddr, inner: &Arc<Inner>) {
    while !inner.stop.load(Ordering::SeqCst) {
        let client = match listener.accept() {
            Ok((s, _)) => s,
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                std::thread::sleep(ACCEPT_POLL);
                continue;
            }
            Err(_) => {
                std::thread::sleep(ACCEPT_POLL);
                continue;
            }
        };
        if !inner.up.load(Ordering::SeqCst) {
            inner.refused.fetch_add(1, Ordering::Relaxed);
            let _ = client.shutdown(Shutdown::Both);
            continue;
        }
        let Ok(server) = TcpStream::connect_timeout(&target, Duration::from_secs(2)) else {
            let _ = client.shutdown(Shutdown::Both);
            continue;
        };
        if client.set_nonblocking(false).is_err() {
            continue;
        }
        let _ = client.set_nodelay(true);
        let _ = server.set_nodelay(true);
        let pumps = (|| -> std::io::Result<_> {
            let (c2, s2) = (client.try_clone()?, server.try_clone()?);
            let mut open = inner.open.lock().unwrap_or_else(|e| e.into_inner());
            open.push(client.try_clone()?);
            open.push(server.try_clone()?);
            Ok((c2, s2))
        })();
        let Ok((c2, s2)) = pumps else {
            continue;
        };
        // A cut that came meanwhile closes this one too.
        if !inner.up.load(Ordering::SeqCst) {
            close_all(inner);
        }
        inner.connections.fetch_add(1, Ordering::Relaxed);
        let _ = std::thread::Builder::new()
            .name("link-proxy-up".into())
            .spawn(move || pump(client, s2));
        let _ = std::thread::Builder::new()
            .name("link-proxy-down".into())
            .spawn(move || pump(server, c2));
    }
}

/// Copies `from` to `to` until either closes; then closes both.
fn pump(mut from: TcpStream, mut to: TcpStream) {
    let mut buf = vec![0u8; 64 * 1024];
    loop {
        match from.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => {
                if to.write_all(&buf[..n]).is_err() {
                    break;
                }
            }
        }
    }
    let _ = from.shutdown(Shutdown::Both);
    let _ = to.shutdown(Shutdown::Both);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_cross_the_proxy_until_a_cut_and_again_once_it_is_restored() {
        let server = TcpListener::bind("127.0.0.1:0").expect("bind");
        let target = server.local_addr().expect("addr");
        let echo = std::thread::spawn(move || {
            for s in server.incoming().take(2) {
                let Ok(mut s) = s else { continue };
                let mut b = [0u8; 5];
                if s.read_exact(&mut b).is_ok() {
                    let _ = s.write_all(&b);
                }
                // Held open until the far side closes.
                let _ = s.read(&mut b);
            }
        });
        let proxy = LinkProxy::start(target).expect("proxy");
        let at = SocketAddr::from(([127, 0, 0, 1], proxy.port()));
        let mut a = TcpStream::connect(at).expect("connect");
        a.write_all(b"hello").expect("write");
        let mut got = [0u8; 5];
        a.read_exact(&mut got).expect("echo");
        assert_eq!(&got, b"hello");

        proxy.cut();
        // The connection under way is closed: a read sees its end.
        a.set_read_timeout(Some(Duration::from_secs(10)))
            .expect("timeout");
        assert!(matches!(a.read(&mut got), Ok(0) | Err(_)));
        // A new one is closed as soon as it is accepted.
        let mut b = TcpStream::connect(at).expect("connect");
        b.set_read_timeout(Some(Duration::from_secs(10)))
            .expect("timeout");
        assert!(matches!(b.read(&mut got), Ok(0) | Err(_)));

        proxy.restore();
        let mut c = TcpStream::connect(at).expect("connect");
        c.write_all(b"again").expect("write");
        c.read_exact(&mut got).expect("echo");
        assert_eq!(&got, b"again");
        drop(c);
        drop(proxy);
        echo.join().expect("echo thread");
        let _ = (a, b);
    }
}
