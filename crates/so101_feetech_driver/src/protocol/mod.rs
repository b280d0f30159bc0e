//! The Feetech STS ("protocol 0") wire protocol: instruction and status packets, the STS3215
//! control table, sign-magnitude registers and bus timing.

mod packet;
mod reader;
pub mod registers;
pub mod timing;

pub use packet::{
    checksum, decode_instruction, decode_status, encode_instruction, encode_status, Instruction,
    ProtocolError, ServoErrors, StatusPacket, BROADCAST_ID, MAX_ID, MAX_PACKET_LEN,
};
pub use reader::{FrameError, PacketReader};
