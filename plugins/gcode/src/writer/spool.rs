//! Layers that wait for the wipe tower's decision (see `Writer::write_layer`), kept in
//! a temporary file so that a long wait holds no layer in memory.

use std::io::Write;

use lamina_api::{Error, LayerPlan, Result};

/// Layers waiting to be written, kept in a temporary file (MessagePack, each behind its
/// length) so that a long wait holds no layer in memory.
#[derive(Default)]
pub(super) struct Spool {
    file: Option<std::fs::File>,
    layers: usize,
}

impl Spool {
    fn error(e: impl std::fmt::Display) -> Error {
        Error::stage(crate::STAGE, format!("spooling layers to a temporary file: {e}"))
    }

    pub(super) fn push(&mut self, plan: &LayerPlan) -> Result<()> {
        let bytes = rmp_serde::to_vec_named(plan).map_err(Self::error)?;
        if self.file.is_none() {
            self.file = Some(tempfile::tempfile().map_err(Self::error)?);
        }
        let file = self.file.as_mut().ok_or_else(|| Self::error("no file"))?;
        file.write_all(&(bytes.len() as u64).to_le_bytes())
            .and_then(|()| file.write_all(&bytes))
            .map_err(Self::error)?;
        self.layers += 1;
        Ok(())
    }

    /// Reads the layers back in order, one at a time, and empties the spool.
    pub(super) fn drain(&mut self, mut each: impl FnMut(LayerPlan) -> Result<()>) -> Result<()> {
        use std::io::{Read, Seek};
        let Some(mut file) = self.file.take() else {
            return Ok(());
        };
        file.seek(std::io::SeekFrom::Start(0)).map_err(Self::error)?;
        let mut reader = std::io::BufReader::new(file);
        for _ in 0..std::mem::take(&mut self.layers) {
            let mut len = [0u8; 8];
            reader.read_exact(&mut len).map_err(Self::error)?;
            let mut bytes = vec![0u8; u64::from_le_bytes(len) as usize];
            reader.read_exact(&mut bytes).map_err(Self::error)?;
            each(rmp_serde::from_slice(&bytes).map_err(Self::error)?)?;
        }
        Ok(())
    }
}
