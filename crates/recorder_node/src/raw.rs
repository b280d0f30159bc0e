//! Messages as they come off the wire: a RustDDS reader whose "deserializer" keeps the CDR bytes
//! instead of decoding them, so the bag holds exactly what the publisher sent (rosbag2 stores the
//! serialized message, never a re-encoding).

use std::convert::Infallible;

use rustdds::{
    no_key::{Decode, DefaultDecoder, DeserializerAdapter},
    RepresentationIdentifier,
};

/// One serialized message: the 4-byte encapsulation header, then the CDR payload. RustDDS hands
/// the representation identifier over apart from the payload and drops the two options bytes,
/// which are therefore written as zero (readers only look at the identifier).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SerializedMessage(pub Vec<u8>);

/// The encodings ROS 2 publishers use (plain and XCDR2, both byte orders).
const ENCODINGS: [RepresentationIdentifier; 6] = [
    RepresentationIdentifier::CDR_LE,
    RepresentationIdentifier::CDR_BE,
    RepresentationIdentifier::PL_CDR_LE,
    RepresentationIdentifier::PL_CDR_BE,
    RepresentationIdentifier::CDR2_LE,
    RepresentationIdentifier::CDR2_BE,
];

pub struct RawAdapter;

impl DeserializerAdapter<SerializedMessage> for RawAdapter {
    type Error = Infallible;
    type Decoded = SerializedMessage;

    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        &ENCODINGS
    }

    fn transform_decoded(decoded: Self::Decoded) -> SerializedMessage {
        decoded
    }
}

#[derive(Debug, Clone, Copy)]
pub struct RawDecoder;

impl<'de> Decode<'de, SerializedMessage> for RawDecoder {
    type Error = Infallible;

    fn decode_bytes(
        self,
        payload: &'de [u8],
        encoding: RepresentationIdentifier,
    ) -> Result<SerializedMessage, Infallible> {
        Ok(SerializedMessage(with_header(payload, encoding)))
    }
}

impl DefaultDecoder<SerializedMessage> for RawAdapter {
    type Decoder = RawDecoder;
    const DECODER: RawDecoder = RawDecoder;
}

fn with_header(payload: &[u8], encoding: RepresentationIdentifier) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(payload.len() + 4);
    bytes.extend_from_slice(&encoding.to_bytes());
    bytes.extend_from_slice(&[0, 0]);
    bytes.extend_from_slice(payload);
    bytes
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_encapsulation_header_is_rebuilt_in_front_of_the_payload() {
        let message = RawDecoder
            .decode_bytes(&[7, 0, 0, 0], RepresentationIdentifier::CDR_LE)
            .unwrap();
        assert_eq!(message.0, [0x00, 0x01, 0x00, 0x00, 7, 0, 0, 0]);
    }
}
