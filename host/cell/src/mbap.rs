//! Modbus TCP framing for the cell's server: the MBAP header, the request PDUs the register map
//! takes, their answers and exceptions, and the connection loop with its timeouts.
//!
//! Why not tokio-modbus's server: its decoder drops the connection on a request it cannot
//! decode (an FC16 of 124 registers, a byte count that does not match the quantity, an FC05
//! with a value other than 0x0000/0xFF00, an unknown MEI type) where the Modbus application
//! protocol answers an exception, and it has no timeouts. Here every well-framed request gets
//! an answer: 0x01 for a function or MEI type the map does not have, 0x03 for a bad quantity,
//! byte count or value, then the register map's own answers ([`RegisterMap::handle`], the
//! cell's `modbus::Registers`). Only a broken frame (protocol id not 0, a length outside
//! 2..=260) or a timeout closes the connection. The request and answer types stay tokio-modbus's.

use std::borrow::Cow;
use std::net::SocketAddr;
use std::time::Duration;

use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
use tokio::net::TcpStream;
use tokio_modbus::{ExceptionCode, Request, Response};

use super::ratelog;

/// Most registers one FC16 write may carry (the Modbus application protocol's limit).
pub const MAX_WRITE: u16 = 123;

/// What the framing serves: a register map that answers decoded requests (the cell's
/// [`crate::modbus::Registers`]). The framing knows nothing of what the registers mean.
pub trait RegisterMap: Send + Sync {
    /// The map's answer to `request`.
    fn handle(
        &self,
        request: Request<'_>,
    ) -> impl std::future::Future<Output = Result<Response, ExceptionCode>> + Send;
    /// What the last command did, for the write log.
    fn last_result(&self) -> String;
}

/// The MBAP length field's largest value taken: the spec's is 254 (the unit id and a PDU of 253
/// bytes), but a client that sends an FC16 of 124 registers (255) gets the spec's exception for
/// the quantity, not a closed connection; beyond this the frame is broken.
pub(crate) const MAX_LENGTH: u16 = 260;
/// How long the rest of a frame may take once its first byte arrived.
pub(crate) const FRAME_TIMEOUT: Duration = Duration::from_secs(2);
/// Function code 0x2B, MEI type 0x0E: read device identification (basic objects).
const FC_MEI: u8 = 0x2B;
const MEI_DEVICE_ID: u8 = 0x0E;

/// A request PDU, decoded.
#[derive(Debug, PartialEq, Eq)]
pub enum Pdu {
    /// A request for the register map.
    Map(Request<'static>),
    /// Read device identification: the read code (1-4) and the first object id.
    DeviceId { code: u8, object: u8 },
}

/// Decodes a request PDU (function code first); the exception to answer when it is not one.
pub fn decode(pdu: &[u8]) -> Result<Pdu, ExceptionCode> {
    let (&function, data) = pdu.split_first().ok_or(ExceptionCode::IllegalFunction)?;
    if pdu.len() > 253 && function != 0x10 {
        return Err(ExceptionCode::IllegalDataValue);
    }
    let word = |i: usize| data.get(i..i + 2).map(|w| u16::from_be_bytes([w[0], w[1]]));
    let pair = || match (data.len(), word(0), word(2)) {
        (4, Some(a), Some(b)) => Ok((a, b)),
        _ => Err(ExceptionCode::IllegalDataValue),
    };
    match function {
        0x03 => pair().map(|(a, n)| Pdu::Map(Request::ReadHoldingRegisters(a, n))),
        0x04 => pair().map(|(a, n)| Pdu::Map(Request::ReadInputRegisters(a, n))),
        0x06 => pair().map(|(a, v)| Pdu::Map(Request::WriteSingleRegister(a, v))),
        0x10 => decode_write_multiple(data),
        // Coils: not in the map, but a value that is no coil value is refused as the spec says.
        0x05 => match pair()? {
            (_, 0x0000 | 0xFF00) => Err(ExceptionCode::IllegalFunction),
            _ => Err(ExceptionCode::IllegalDataValue),
        },
        FC_MEI => match data {
            [MEI_DEVICE_ID, code @ 1..=4, object] => {
                Ok(Pdu::DeviceId { code: *code, object: *object })
            }
            [MEI_DEVICE_ID, ..] => Err(ExceptionCode::IllegalDataValue),
            _ => Err(ExceptionCode::IllegalFunction),
        },
        _ => Err(ExceptionCode::IllegalFunction),
    }
}

/// FC16: address, quantity (1..=[`MAX_WRITE`]), byte count (twice the quantity), values.
fn decode_write_multiple(data: &[u8]) -> Result<Pdu, ExceptionCode> {
    let bad = ExceptionCode::IllegalDataValue;
    let [a0, a1, q0, q1, count, values @ ..] = data else { return Err(bad) };
    let quantity = u16::from_be_bytes([*q0, *q1]);
    if quantity == 0 || quantity > MAX_WRITE || usize::from(*count) != 2 * usize::from(quantity) {
        return Err(bad);
    }
    if values.len() != usize::from(*count) {
        return Err(bad);
    }
    let values: Vec<u16> =
        values.chunks_exact(2).map(|w| u16::from_be_bytes([w[0], w[1]])).collect();
    Ok(Pdu::Map(Request::WriteMultipleRegisters(
        u16::from_be_bytes([*a0, *a1]),
        Cow::Owned(values),
    )))
}

/// The answer PDU to a map request's outcome (`function`: the request's code).
pub fn encode(function: u8, answer: &Result<Response, ExceptionCode>) -> Vec<u8> {
    let registers = |out: &mut Vec<u8>, values: &[u16]| {
        out.push(u8::try_from(values.len() * 2).unwrap_or(u8::MAX));
        out.extend(values.iter().flat_map(|v| v.to_be_bytes()));
    };
    let mut out = vec![function];
    match answer {
        Err(code) => return exception(function, *code),
        Ok(Response::ReadHoldingRegisters(values) | Response::ReadInputRegisters(values)) => {
            registers(&mut out, values);
        }
        Ok(Response::WriteSingleRegister(a, b) | Response::WriteMultipleRegisters(a, b)) => {
            out.extend(a.to_be_bytes());
            out.extend(b.to_be_bytes());
        }
        Ok(_) => return exception(function, ExceptionCode::ServerDeviceFailure),
    }
    out
}

/// An exception PDU.
pub fn exception(function: u8, code: ExceptionCode) -> Vec<u8> {
    vec![function | 0x80, u8::from(code)]
}

/// Read device identification, basic objects: vendor, product, revision.
pub(crate) fn device_id(code: u8, object: u8) -> Vec<u8> {
    let objects: [(u8, &str); 3] =
        [(0, "chladni"), (1, "chladni serve"), (2, env!("CARGO_PKG_VERSION"))];
    let chosen: Vec<(u8, &str)> = if code == 4 {
        match objects.iter().find(|(id, _)| *id == object) {
            Some(one) => vec![*one],
            None => return exception(FC_MEI, ExceptionCode::IllegalDataAddress),
        }
    } else {
        objects.iter().copied().filter(|(id, _)| *id >= object.min(2)).collect()
    };
    let mut out = vec![FC_MEI, MEI_DEVICE_ID, code, 0x01, 0x00, 0x00];
    out.push(u8::try_from(chosen.len()).unwrap_or(0));
    for (id, text) in chosen {
        out.push(id);
        out.push(u8::try_from(text.len()).unwrap_or(0));
        out.extend(text.as_bytes());
    }
    out
}

/// What one request is, for the log: short, whatever its size.
fn describe(request: &Request<'_>) -> String {
    match request {
        Request::WriteSingleRegister(a, v) => format!("FC06 write {v} at {a}"),
        Request::WriteMultipleRegisters(a, v) => format!("FC16 write of {} at {a}", v.len()),
        other => format!("{other:?}"),
    }
}

/// Serves one connection until it closes, breaks a frame, or stays silent for `idle`.
pub async fn connection(
    mut stream: TcpStream,
    peer: SocketAddr,
    registers: impl RegisterMap,
    idle: Duration,
) {
    let client = peer.ip().to_string();
    let log = |cause: &'static str, text: String| ratelog::global().log(&client, cause, &text);
    loop {
        let mut header = [0u8; 7];
        match tokio::time::timeout(idle, stream.read_exact(&mut header[..1])).await {
            Ok(Ok(_)) => {}
            Ok(Err(_)) => return,
            Err(_) => {
                return log(
                    "idle",
                    format!("modbus {peer}: closed after {idle:?} without a request"),
                );
            }
        }
        let rest = tokio::time::timeout(FRAME_TIMEOUT, stream.read_exact(&mut header[1..])).await;
        let [t0, t1, p0, p1, l0, l1, unit] = header;
        let length = u16::from_be_bytes([l0, l1]);
        if !matches!(rest, Ok(Ok(_))) || [p0, p1] != [0, 0] || !(2..=MAX_LENGTH).contains(&length) {
            return log(
                "frame",
                format!(
                    "modbus {peer}: closed: not a Modbus TCP header (protocol {}, length {length}) or too slow",
                    u16::from_be_bytes([p0, p1])
                ),
            );
        }
        let mut pdu = vec![0u8; usize::from(length) - 1];
        if !matches!(
            tokio::time::timeout(FRAME_TIMEOUT, stream.read_exact(&mut pdu)).await,
            Ok(Ok(_))
        ) {
            return log(
                "frame",
                format!(
                    "modbus {peer}: closed: the frame promised {length} bytes and did not send them within {FRAME_TIMEOUT:?}"
                ),
            );
        }
        let answer = answer(&pdu, &registers, &peer, &log).await;
        let mut frame = Vec::with_capacity(7 + answer.len());
        frame.extend([t0, t1, 0, 0]);
        frame.extend(u16::try_from(answer.len() + 1).unwrap_or(MAX_LENGTH).to_be_bytes());
        frame.push(unit);
        frame.extend(answer);
        if stream.write_all(&frame).await.is_err() {
            return;
        }
    }
}

async fn answer(
    pdu: &[u8],
    registers: &impl RegisterMap,
    peer: &SocketAddr,
    log: &impl Fn(&'static str, String),
) -> Vec<u8> {
    let function = pdu.first().copied().unwrap_or(0);
    match decode(pdu) {
        Err(code) => {
            log(
                "refused",
                format!(
                    "modbus {peer}: function {function:#04x} refused: exception {:#04x} ({code:?})",
                    u8::from(code)
                ),
            );
            exception(function, code)
        }
        Ok(Pdu::DeviceId { code, object }) => device_id(code, object),
        Ok(Pdu::Map(request)) => {
            let write = matches!(
                request,
                Request::WriteSingleRegister(..) | Request::WriteMultipleRegisters(..)
            );
            let described = write.then(|| describe(&request));
            let answer = registers.handle(request).await;
            // Writes change the cell: the operator sees them on stderr (rate-limited).
            if let Some(request) = described {
                let (cause, outcome) = match &answer {
                    Ok(_) => ("write", "ok".to_owned()),
                    Err(e) => ("write-refused", format!("exception {:#04x} ({e:?})", u8::from(*e))),
                };
                let result = registers.last_result();
                log(cause, format!("modbus {peer}: {request} → {outcome}, result {result}"));
            }
            encode(function, &answer)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_quantities_byte_counts_and_values_are_0x03_unknown_functions_0x01() {
        let value = Err(ExceptionCode::IllegalDataValue);
        let function = Err(ExceptionCode::IllegalFunction);
        // FC16 of 124 registers (one more than the spec's 123).
        let mut fc16 = vec![0x10, 0, 0, 0, 124, 248];
        fc16.extend(vec![0; 248]);
        assert_eq!(decode(&fc16), value);
        // A byte count that does not match the quantity, or the values sent.
        assert_eq!(decode(&[0x10, 0, 0, 0, 2, 3, 0, 1, 0, 2, 0]), value);
        assert_eq!(decode(&[0x10, 0, 0, 0, 2, 4, 0, 1, 0]), value);
        assert_eq!(decode(&[0x05, 0, 0, 0x12, 0x34]), value);
        assert_eq!(decode(&[0x05, 0, 0, 0xFF, 0x00]), function);
        assert_eq!(decode(&[0x2B, 0x0D, 0, 0]), function);
        assert_eq!(decode(&[0x2B, 0x0E, 7, 0]), value);
        assert_eq!(decode(&[0x01, 0, 0, 0, 1]), function);
        assert_eq!(decode(&[0x03, 0, 0, 0]), value);
        assert_eq!(decode(&[]), function);
        let good = decode(&[0x10, 0, 1, 0, 2, 4, 0, 1, 0, 2]).unwrap();
        assert_eq!(good, Pdu::Map(Request::WriteMultipleRegisters(1, Cow::Owned(vec![1, 2]))));
        assert_eq!(exception(0x10, ExceptionCode::IllegalDataValue), [0x90, 0x03]);
    }

    #[test]
    fn device_identification_lists_the_basic_objects() {
        let id = device_id(1, 0);
        assert_eq!(&id[..7], &[0x2B, 0x0E, 1, 0x01, 0, 0, 3]);
        assert_eq!(&id[7..9], &[0, 7]);
        assert_eq!(&id[9..16], b"chladni");
        assert_eq!(device_id(4, 9), [0xAB, 0x02]);
    }
}
