//! The frames on a child plugin's pipes: one byte saying what the frame is, its length
//! (4 bytes, little-endian) and that many bytes. The bytes of requests and replies are
//! the MessagePack of the boundary, unchanged.

use std::io::{self, Read, Write};

/// Host to child: a request for the plugin ([`crate::plugin::Request`] bytes).
pub(crate) const CALL: u8 = 1;
/// Host to child: a handle the host no longer needs (8 bytes, little-endian).
pub(crate) const RELEASE: u8 = 2;
/// Host to child: the answer to a service request ([`crate::plugin::HostReply`]
/// bytes; empty when the host could not encode one).
pub(crate) const SERVICE_REPLY: u8 = 3;

/// Child to host: the library is loaded; the bytes are the plugin's name.
pub(crate) const READY: u8 = 10;
/// Child to host: the library was refused; the bytes are the reason.
pub(crate) const REFUSED: u8 = 11;
/// Child to host: the plugin's reply to a call ([`crate::plugin::Reply`] bytes).
pub(crate) const REPLY: u8 = 12;
/// Child to host: the plugin's call failed without a reply.
pub(crate) const FAILED: u8 = 13;
/// Child to host: the plugin asks for a service during a call
/// ([`crate::plugin::HostRequest`] bytes).
pub(crate) const SERVICE: u8 = 14;

/// Writes one frame and flushes it.
pub(crate) fn write(out: &mut impl Write, kind: u8, bytes: &[u8]) -> io::Result<()> {
    let len = u32::try_from(bytes.len()).map_err(|_| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "a message of {} bytes is larger than a frame (4 GiB)",
                bytes.len()
            ),
        )
    })?;
    let mut header = [0u8; 5];
    header[0] = kind;
    header[1..].copy_from_slice(&len.to_le_bytes());
    out.write_all(&header)?;
    out.write_all(bytes)?;
    out.flush()
}

/// Reads one frame. The buffer grows with the bytes that arrive, not with the length
/// the header claims, so a lying peer cannot make it allocate what it never sends.
pub(crate) fn read(input: &mut impl Read) -> io::Result<(u8, Vec<u8>)> {
    let mut header = [0u8; 5];
    input.read_exact(&mut header)?;
    let len = u32::from_le_bytes([header[1], header[2], header[3], header[4]]) as u64;
    let mut bytes = Vec::new();
    input.take(len).read_to_end(&mut bytes)?;
    if bytes.len() as u64 != len {
        return Err(io::Error::new(
            io::ErrorKind::UnexpectedEof,
            format!("a frame ended after {} of its {len} bytes", bytes.len()),
        ));
    }
    Ok((header[0], bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_reads_back_as_written() {
        let mut buf = Vec::new();
        write(&mut buf, CALL, b"hello").unwrap();
        write(&mut buf, RELEASE, &7u64.to_le_bytes()).unwrap();
        assert_eq!(buf.len(), 5 + 5 + 5 + 8);
        let mut r = &buf[..];
        assert_eq!(read(&mut r).unwrap(), (CALL, b"hello".to_vec()));
        assert_eq!(read(&mut r).unwrap(), (RELEASE, 7u64.to_le_bytes().to_vec()));
        assert_eq!(read(&mut r).unwrap_err().kind(), io::ErrorKind::UnexpectedEof);
    }

    #[test]
    fn a_frame_shorter_than_its_header_says_is_an_error_without_the_claimed_allocation() {
        let mut buf = vec![REPLY];
        buf.extend_from_slice(&u32::MAX.to_le_bytes());
        buf.extend_from_slice(b"abc");
        let e = read(&mut &buf[..]).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::UnexpectedEof);
        assert!(e.to_string().contains("after 3 of its 4294967295 bytes"), "{e}");
    }
}
