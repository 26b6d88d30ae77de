/* vtz as a decompressor of GDAL's Zarr driver.
 *
 * A Zarr format 2 array written with vtz's numcodecs codec (Python:
 * `compressors=vtz.numcodecs.Vtz(max_error=1)`) names `{"id": "vtz", ...}` as its
 * compressor; each chunk is a self-describing .vtz stream of the chunk's shape and dtype.
 * GDAL (3.4 and later) looks compressors up by that id in a registry that plugins may add
 * to (CPLRegisterDecompressor), so with this plugin loaded `gdalinfo`, `gdal_translate` and
 * osgeo.gdal read such stores. Only decoding is registered: GDAL writes Zarr with its own
 * compressors.
 */
#include "cpl_compressor.h"
#include "cpl_error.h"
#include "cpl_vsi.h"
#include "vtz.h"

#include <algorithm>
#include <cstdint>
#include <limits>

namespace
{

size_t BytesPerSample(int32_t type)
{
    switch (type)
    {
        case VTZ_U8:
            return 1;
        case VTZ_I16:
        case VTZ_U16:
            return 2;
        case VTZ_I32:
        case VTZ_F32:
            return 4;
        default:
            return 8;
    }
}

/* The callback GDAL calls per chunk (cpl_compressor.h explains the three ways of giving
 * the output buffer). The chunk decodes in its own type, row-major, nodata samples as the
 * nodata value: what the Python codec's decode returns. */
bool VTZDecompress(const void *input_data, size_t input_size, void **output_data,
                   size_t *output_size, CSLConstList /* options */, void * /* user */)
{
    if (input_data == nullptr || output_size == nullptr)
        return false;
    // A chunk's header may claim any size, and a few bytes may legally code a huge constant
    // raster: the samples it may decode to are bounded before anything is allocated, by
    // the buffer GDAL gives (its chunk size), else by 2^26 samples.
    VtzLimits sLimits{};
    sLimits.max_samples = (output_data != nullptr && *output_data != nullptr)
                              ? std::max<uint64_t>(1, *output_size)
                              : (uint64_t{1} << 26);
    VtzFile *file = nullptr;
    if (vtz_open_memory(static_cast<const uint8_t *>(input_data), input_size, &sLimits,
                        &file) != VTZ_OK)
    {
        CPLError(CE_Failure, CPLE_AppDefined, "vtz chunk: %s", vtz_last_error());
        *output_size = 0;
        return false;
    }
    VtzInfo info;
    if (vtz_get_info(file, &info) != VTZ_OK)
    {
        CPLError(CE_Failure, CPLE_AppDefined, "vtz chunk: %s", vtz_last_error());
        vtz_close(file);
        *output_size = 0;
        return false;
    }
    const size_t bps = BytesPerSample(info.sample_type);
    const uint64_t samples = static_cast<uint64_t>(info.width) * info.height;
    if (samples > std::numeric_limits<size_t>::max() / bps)
    {
        CPLError(CE_Failure, CPLE_AppDefined, "vtz chunk: too large");
        vtz_close(file);
        *output_size = 0;
        return false;
    }
    const size_t need = static_cast<size_t>(samples) * bps;
    if (output_data == nullptr)
    {
        /* Only the size is asked. */
        *output_size = need;
        vtz_close(file);
        return true;
    }
    bool allocated = false;
    if (*output_data == nullptr)
    {
        *output_data = VSI_MALLOC_VERBOSE(need ? need : 1);
        if (*output_data == nullptr)
        {
            vtz_close(file);
            *output_size = 0;
            return false;
        }
        allocated = true;
    }
    else if (*output_size < need)
    {
        CPLError(CE_Failure, CPLE_AppDefined,
                 "vtz chunk: %u x %u samples need %zu bytes, the chunk buffer has %zu",
                 info.width, info.height, need, *output_size);
        *output_size = need;
        vtz_close(file);
        return false;
    }
    const int32_t rc = vtz_read(file, 0, 0, info.width, info.height, info.sample_type,
                                *output_data, need, 1);
    vtz_close(file);
    if (rc != VTZ_OK)
    {
        CPLError(CE_Failure, CPLE_AppDefined, "vtz chunk: %s", vtz_last_error());
        if (allocated)
        {
            VSIFree(*output_data);
            *output_data = nullptr;
        }
        *output_size = 0;
        return false;
    }
    *output_size = need;
    return true;
}

/* GDAL's Zarr driver opens an array only when its compressor id names both a compressor
 * and a decompressor. A compressor gets a chunk's bytes without its shape, and vtz codes
 * 2-D rasters, so this one refuses with a message that says how to write such stores. */
bool VTZCompress(const void *, size_t, void **, size_t *output_size, CSLConstList, void *)
{
    CPLError(CE_Failure, CPLE_NotSupported,
             "vtz: GDAL cannot write vtz-compressed Zarr chunks (a compressor is not given "
             "the chunk's shape); write the store with vtz's Python codec "
             "(vtz.numcodecs.Vtz), or write a .vtz with gdal_translate -of VTZ");
    if (output_size != nullptr)
        *output_size = 0;
    return false;
}

}  // namespace

/* Called from GDALRegister_VTZ (vtzdataset.cpp): registers the "vtz" decompressor (and the
 * compressor that explains why it cannot compress) once. */
void VTZRegisterZarrDecompressor()
{
    CPLCompressor s;
    s.nStructVersion = 1;
    s.pszId = "vtz";
    s.eType = CCT_COMPRESSOR;
    s.papszMetadata = nullptr;
    s.user_data = nullptr;
    if (CPLGetDecompressor("vtz") == nullptr)
    {
        s.pfnFunc = VTZDecompress;
        CPLRegisterDecompressor(&s);
    }
    if (CPLGetCompressor("vtz") == nullptr)
    {
        s.pfnFunc = VTZCompress;
        CPLRegisterCompressor(&s);
    }
}
