//! PLUS toolkit files: tracked-ultrasound sequence metafiles (`.mha` / `.seq.mha`) and
//! the device-set configuration XML that holds the spatial calibration.
//!
//! No maintained Rust crate reads either, so this is a small reader/writer of our own,
//! following the PLUS documentation ("Sequence file", "Ultrasound image orientation",
//! "Definition of commonly used coordinate systems") and PLUS's own
//! `vtkPlusMetaImageSequenceIO`.
//!
//! # Sequence metafile
//! A MetaIO text header of `Key = Value` lines (`ObjectType = Image` first,
//! `ElementDataFile = LOCAL` last), then the pixel data of every frame, row-major, frame
//! after frame: raw, or one zlib stream (`CompressedData = True`, `CompressedDataSize`
//! bytes) over all frames. `DimSize` is `width height frames` (`NDims = 3`; `NDims = 4`
//! with `width height 1 frames` is accepted too). Per frame `k` (index written with at
//! least four digits, `Seq_Frame0007_...`):
//! * `<From>To<To>Transform`: 16 numbers, row-major, last row `0 0 0 1`;
//! * `<From>To<To>TransformStatus`: `OK`, or anything else (`INVALID`, `MISSING`, ...);
//!   a frame whose status is not `OK` is *skipped and counted*, not an error (no status
//!   field at all counts as `OK`, as in old PLUS files);
//! * `Timestamp` (s, PLUS's filtered time stamp), optional `UnfilteredTimestamp`,
//!   `FrameNumber` and `ImageStatus` (a frame whose image status is not `OK` is skipped
//!   and counted as well).
//!
//! Only `ElementType = MET_UCHAR` with one channel is read: the images are bone masks
//! (0 background, anything else bone), not B-mode intensities. `BinaryData` must be
//! `True`; `BinaryDataByteOrderMSB` does not matter for one-byte elements;
//! `ElementSpacing` is ignored (PLUS keeps the pixel scale in the calibration).
//!
//! `UltrasoundImageOrientation` (`MF`, `MN`, `UF`, `UN`, or a three-letter 3-D code whose
//! third letter is ignored for 2-D frames) says where the stored image's `+x` (columns)
//! and `+y` (rows) point: `M`/`U` = towards the marked/unmarked side of the transducer,
//! `F`/`N` = away from/towards the transducer. PLUS works in `MF` internally and its
//! calibration (`ImageToProbe`) refers to the `MF` image, so [`SequenceReader`] hands out
//! every frame re-oriented to `MF`: columns reversed for `U`, rows reversed for `N`. Row 0
//! is then at the probe face (near field) and rows count into depth (Near → Far), which is
//! what ribreg's image frame needs. A file without the field is taken as `MF` (what PLUS
//! writes) and [`SequenceInfo::orientation_given`] says so. RF orientations (`FM`, ...)
//! are refused.
//!
//! ## Bounded memory
//! The reader streams: [`SequenceReader::open`] checks the whole header line by line
//! (one line in memory, never more than [`MAX_LINE_BYTES`]) and the data size against the
//! file, then [`SequenceReader::next_frame`] reads one frame's header fields (a second
//! cursor over the header) and one frame's pixels (raw, or inflated from the zlib stream)
//! at a time into one frame buffer of at most [`MAX_FRAME_PIXELS`] bytes. Nothing is
//! allocated from what `DimSize` claims beyond that one frame, and a claim over the caps
//! is refused before anything is read. Frame fields must come grouped by frame in
//! increasing frame order, as PLUS (and 3D Slicer) write them.
//!
//! # Device-set configuration
//! [`read_plus_transform`] finds `<CoordinateDefinitions><Transform From=".." To=".."
//! Matrix=".."/>` (or its inverse) in a PLUS configuration file; [`write_plus_config`]
//! writes a minimal configuration holding an `ImageToProbe` calibration.

mod config;
mod sequence;
#[cfg(test)]
mod tests;

pub use config::{
    read_plus_transform, write_plus_config, PlusConfigError, PlusConfigProblem, MAX_CONFIG_BYTES,
};
pub use sequence::{
    FrameOut, Matrix4, Orientation, SequenceError, SequenceErrorKind, SequenceFrame, SequenceInfo,
    SequenceReader, SequenceSpec, SequenceWriter, Status, MAX_FRAMES, MAX_FRAME_PIXELS,
    MAX_HEADER_BYTES, MAX_LINE_BYTES, MAX_SIDE_PX,
};
