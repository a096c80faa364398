//! The socketcand client against a scripted server and against the virtual car's server.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::thread;
use std::time::{Duration, Instant as WallInstant};

use autoplug_can::Frame;
use autoplug_transport::socketcand::SocketcandClient;
use autoplug_transport::{Incoming, Timestamp, Transport, TransportError};
use autoplug_virtual_car::socketcand::SocketcandServer;

const TIMEOUT: Duration = Duration::from_secs(5);

/// The next thing the client hands over, which must be a frame.
fn next_frame(client: &mut SocketcandClient) -> (Frame, Timestamp) {
    match client.recv(TIMEOUT).unwrap() {
        Some(Incoming::Frame(frame, time)) => (frame, time),
        other => panic!("expected a frame, got {other:?}"),
    }
}

/// Reads one `< ... >` message from a scripted server's side of the connection.
fn read_message(reader: &mut impl Read) -> String {
    let mut text = Vec::new();
    let mut byte = [0u8; 1];
    loop {
        reader.read_exact(&mut byte).expect("a message");
        text.push(byte[0]);
        if byte[0] == b'>' {
            return String::from_utf8(text).unwrap().trim().to_string();
        }
    }
}

/// A scripted socketcand server on a free port: runs `script` on the first connection.
fn scripted(script: impl FnOnce(TcpStream) + Send + 'static) -> (u16, thread::JoinHandle<()>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let handle = thread::spawn(move || {
        let (stream, _) = listener.accept().unwrap();
        script(stream);
    });
    (port, handle)
}

#[test]
fn frames_both_ways_with_a_scripted_server() {
    let (port, server) = scripted(|mut stream| {
        stream.write_all(b"< hi >").unwrap();
        assert_eq!(read_message(&mut stream), "< open can0 >");
        stream.write_all(b"< ok >").unwrap();
        assert_eq!(read_message(&mut stream), "< rawmode >");
        stream.write_all(b"< ok >").unwrap();
        assert_eq!(read_message(&mut stream), "< echo >");
        // A frame before the echo's answer is kept.
        stream.write_all(b"< frame 100 11.0 AA >< echo >").unwrap();
        // Two frames in one write, a skipped extended one, an echo in between.
        stream
            .write_all(b"< frame 78D 12.000100 0250030032 >< echo >< frame 18DAF10D 12.1 01 >< frame 123 13.5  >")
            .unwrap();
        assert_eq!(
            read_message(&mut stream),
            "< send 70D 8 02 10 03 cc cc cc cc cc >"
        );
        // A frame split across two writes.
        stream.write_all(b"< frame 7E8 14.0 0341").unwrap();
        thread::sleep(Duration::from_millis(20));
        stream.write_all(b"0D57 >").unwrap();
        let mut rest = Vec::new();
        let _ = stream.read_to_end(&mut rest); // until the client hangs up
    });
    let mut client = SocketcandClient::connect("127.0.0.1", port, "can0", TIMEOUT).unwrap();
    assert_eq!(
        client.describe(),
        format!("socketcand 127.0.0.1:{port} bus can0")
    );
    let (frame, _) = next_frame(&mut client);
    assert_eq!(frame, Frame::new(0x100, &[0xAA]).unwrap());

    let (frame, time) = next_frame(&mut client);
    assert_eq!(
        frame,
        Frame::new(0x78D, &[0x02, 0x50, 0x03, 0x00, 0x32]).unwrap()
    );
    assert_eq!(time.bus_us, Some(12_000_100));
    let (frame, time) = next_frame(&mut client);
    assert_eq!(frame, Frame::new(0x123, &[]).unwrap());
    assert_eq!(time.bus_us, Some(13_500_000));
    assert_eq!(client.skipped(), 2, "the echo and the 29-bit frame");

    let request = Frame::new(0x70D, &[0x02, 0x10, 0x03, 0xCC, 0xCC, 0xCC, 0xCC, 0xCC]).unwrap();
    let sent_at = WallInstant::now();
    assert!(client.send(&request).unwrap());
    // The server never echoes it: the client confirms it once the bus could have sent it
    // (an 8-byte frame at 500 kbit/s takes about a quarter of a millisecond).
    assert_eq!(client.recv(TIMEOUT).unwrap(), Some(Incoming::Sent));
    let confirmed_after = sent_at.elapsed();
    assert!(
        confirmed_after >= Duration::from_micros(220)
            && confirmed_after < Duration::from_millis(15),
        "{confirmed_after:?}"
    );
    let (frame, _) = next_frame(&mut client);
    assert_eq!(frame, Frame::new(0x7E8, &[0x03, 0x41, 0x0D, 0x57]).unwrap());
    // Nothing more: a timeout is not an error.
    let started = WallInstant::now();
    assert!(client.recv(Duration::from_millis(30)).unwrap().is_none());
    assert!(started.elapsed() >= Duration::from_millis(25));
    assert!(client.recv(Duration::ZERO).unwrap().is_none());
    drop(client);
    server.join().unwrap();
}

#[test]
fn handshake_failures_are_clear() {
    // The server has no such bus.
    let (port, server) = scripted(|mut stream| {
        stream.write_all(b"< hi >").unwrap();
        let _ = read_message(&mut stream);
        stream
            .write_all(b"< error could not open bus 'can7': this server has can0 >")
            .unwrap();
    });
    let error = SocketcandClient::connect("127.0.0.1", port, "can7", TIMEOUT).unwrap_err();
    assert!(matches!(error, TransportError::Refused { .. }), "{error:?}");
    let text = error.to_string();
    assert!(text.contains("refused 'open can7'"), "{text}");
    assert!(text.contains("this server has can0"), "{text}");
    server.join().unwrap();

    // Not a socketcand server at all.
    let (port, server) = scripted(|mut stream| {
        stream.write_all(b"SSH-2.0-OpenSSH_9.6\r\n").unwrap();
        thread::sleep(Duration::from_millis(300));
    });
    let error = SocketcandClient::connect("127.0.0.1", port, "can0", Duration::from_millis(200))
        .unwrap_err()
        .to_string();
    assert!(error.contains("is it a socketcand server?"), "{error}");
    server.join().unwrap();

    // A malformed frame once in raw mode.
    let (port, server) = scripted(|mut stream| {
        stream.write_all(b"< hi >").unwrap();
        let _ = read_message(&mut stream);
        stream.write_all(b"< ok >").unwrap();
        let _ = read_message(&mut stream);
        stream.write_all(b"< ok >").unwrap();
        assert_eq!(read_message(&mut stream), "< echo >");
        // A server that does not know echo: the client goes on after a while.
        thread::sleep(Duration::from_millis(600));
        stream.write_all(b"< frame 12Z 1.0 00 >").unwrap();
        thread::sleep(Duration::from_millis(100));
    });
    let started = WallInstant::now();
    let mut client = SocketcandClient::connect("127.0.0.1", port, "can0", TIMEOUT).unwrap();
    assert!(started.elapsed() >= Duration::from_millis(450));
    let error = client.recv(TIMEOUT).unwrap_err().to_string();
    assert!(
        error.contains("malformed message '< frame 12Z 1.0 00 >'"),
        "{error}"
    );
    assert!(error.contains("'12Z' is not hexadecimal"), "{error}");
    // Then the server hangs up.
    let error = client.recv(TIMEOUT).unwrap_err();
    assert!(matches!(error, TransportError::Closed(_)), "{error:?}");
    server.join().unwrap();

    // Nobody listening.
    let free = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let error = SocketcandClient::connect("127.0.0.1", free, "can0", TIMEOUT)
        .unwrap_err()
        .to_string();
    assert!(
        error.contains(&format!(
            "cannot connect to the socketcand server at 127.0.0.1:{free}"
        )),
        "{error}"
    );
}

#[test]
fn frames_both_ways_with_the_virtual_cars_server() {
    let server = SocketcandServer::start("127.0.0.1:0").unwrap();
    let address = server.address();
    let mut client =
        SocketcandClient::connect("127.0.0.1", address.port(), "can0", TIMEOUT).unwrap();
    assert!(
        server.wait_for_raw_client(TIMEOUT),
        "the client never reached raw mode"
    );

    let from_car = Frame::new(0x78D, &[0x06, 0x50, 0x03, 0x00, 0x32, 0x01, 0xF4, 0xCC]).unwrap();
    server.broadcast(1_234_567, &from_car, None);
    let empty = Frame::new(0x7FF, &[]).unwrap();
    server.broadcast(1_300_000, &empty, None);
    let (frame, time) = next_frame(&mut client);
    assert_eq!(frame, from_car);
    assert_eq!(time.bus_us, Some(1_234_567));
    assert_eq!(next_frame(&mut client).0, empty);

    let to_car = Frame::new(0x7DF, &[0x02, 0x3E, 0x80, 0xCC, 0xCC, 0xCC, 0xCC, 0xCC]).unwrap();
    assert!(client.send(&to_car).unwrap());
    assert!(client.send(&empty).unwrap());
    let give_up = WallInstant::now() + TIMEOUT;
    let mut received = Vec::new();
    while received.len() < 2 && WallInstant::now() < give_up {
        match server.try_recv() {
            Some(sent) => received.push(sent.frame),
            None => thread::sleep(Duration::from_millis(2)),
        }
    }
    assert_eq!(received, [to_car, empty]);
    assert_eq!(server.refused_commands(), 0);
}
