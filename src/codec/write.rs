//! Decodes written straight to a file without holding the raster: a `.vtz` into a tiled
//! GeoTIFF band by band ([`Decoder::decode_to_geotiff`]), in the memory of one band of tiles.

use super::Decoder;
use crate::error::{Error, Result};
use crate::formats::{self, GeoTiffWriter, PendingFile};
use crate::model::Window;
use std::path::Path;

impl Decoder {
    /// Decode with the options set ([`Decoder::options`]) band by band
    /// ([`Decoder::decode_bands`]) into a tiled GeoTIFF at `path`, written atomically (a
    /// temporary renamed into place once complete) with the PAM `.aux.xml` beside it when its
    /// CRS needs one ([`formats::geotiff_sidecar`]). An existing `path` is replaced only with
    /// `force`. `progress` gets the fraction decoded (0..=1). Returns the window written (the
    /// whole raster without [`DecodeOptions::window`](crate::DecodeOptions::window)).
    ///
    /// Errors: those of [`Decoder::decode_bands`] (a `scale` cannot stream), an existing
    /// output without `force` ([`Error::InvalidArgument`]), and writing the output
    /// ([`Error::Io`]).
    pub fn decode_to_geotiff(
        &mut self,
        path: &Path,
        force: bool,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Result<Window> {
        let (w, h) = (self.info().width as usize, self.info().height as usize);
        let win = self.opts.window.unwrap_or(Window::full(w, h));
        let mut out = PendingFile::create(path, force)?;
        let mut writer = None;
        let mut georef = None;
        let mut file = Some(out.writer());
        self.decode_bands(
            &mut |band| {
                let writer = match (&mut writer, file.take()) {
                    (Some(wr), _) => wr,
                    (slot, Some(f)) => {
                        // The output's georeferencing: the first band's (the window's corner).
                        georef = band.georef.clone();
                        slot.insert(GeoTiffWriter::new(f, win.width, win.height, &band)?)
                    }
                    (None, None) => return Err(Error::invalid("no GeoTIFF writer")),
                };
                writer.write_rows(&band)
            },
            progress,
        )?;
        writer
            .ok_or_else(|| Error::invalid("the decode gave no band to write"))?
            .finish()?;
        out.commit()?;
        if let Some(aux) = formats::geotiff_sidecar(path, georef.as_ref()) {
            formats::write_file(&aux.path, aux.bytes, true)?;
        }
        Ok(win)
    }
}
