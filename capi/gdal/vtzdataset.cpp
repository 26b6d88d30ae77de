/*
 * vtzdataset.cpp: the GDAL raster driver for `.vtz` files (plugin gdal_VTZ.so).
 *
 * A thin C++ shim over vtz's C ABI (capi/include/vtz.h); all decoding and encoding is
 * done by the Rust library, linked statically into the plugin. Built by
 * capi/build-gdal-plugin.sh, checked by capi/gdal/check.sh.
 *
 * What GDAL sees:
 * - Identify: the 8-byte magic `\x89VTZ\r\n\x1a\n`. Format versions 1 (untiled raster)
 *   and 2 (tiled raster) open; version 3 (a point set) is refused with a clear error.
 * - Every path, local or /vsi (/vsicurl/, /vsis3/, an archive, memory), is read by byte
 *   ranges through GDAL's VSI layer (vtz_open_reader with VSIReadRanges): opening reads
 *   the first 64 KB (the header; a version-4 file's tile index) and a version-2 file's
 *   tile index, a read the blocks of the tiles it touches. Identify needs only GDAL's
 *   first bytes. On a network file system (VSIHasOptimizedReadMultiRange) tile blocks are
 *   fetched exactly with VSIFReadMultiRangeL and kept (VTZ_REMOTE_CACHE_MB, default 64),
 *   and a full-resolution window that is not a full-width swath is decoded exactly (only
 *   the tiles it touches; block-aligned reads also need the neighbours' margins).
 * - One read-only band of the file's values (the smallest type that holds them; or its
 *   integer codes with the value mapping as the band's offset and scale: VtzInfo's
 *   value_type, vtz_read_band), with nodata, geotransform, CRS,
 *   AREA_OR_POINT, and the GDAL_METADATA XML applied as the GTiff driver applies its
 *   GDAL_METADATA tag (dataset items, band items: description, unit type, offset, scale,
 *   metadata, per domain).
 * - IMAGE_STRUCTURE metadata (as GTiff reports LERC): COMPRESSION=VTZ, MAX_Z_ERROR (the
 *   bound the file guarantees, 0 = lossless), VTZ_TILED=YES/NO, VTZ_VERSION.
 * - Blocks: a version-2 tile is a GDAL block (edge blocks padded with nodata, or 0), so a
 *   read decodes only the tiles it touches. A version-1 file is decoded whole on the
 *   first read and cached; its blocks are strips of full rows served from that cache.
 * - Overviews from the format itself (when the file has no external .ovr; the
 *   VTZ_OVERVIEWS=NO configuration option turns them off): levels 1, 2, ... down to about
 *   64 samples, level K holding every 2^K-th sample of every 2^K-th row
 *   (vtz_read_overview), for which the residual layer decodes only its coarse levels.
 *   They are VTZRasterBand objects of their own level: blocks of a tile's core at that
 *   level (tiled files) or strips served from a whole-level cache (untiled files; taken
 *   from the full-resolution cache without a decode when that is there).
 * - Full-resolution RasterIO: a version-1 read copies from the cache; a version-2 read
 *   whose tiles are not all cached is either one vtz_read of exactly the window (a small
 *   window: vtz decodes only the rows and columns it needs) or one vtz_read of its
 *   missing tiles (decoded in parallel) stored as blocks (see VTZRasterBand::IRasterIO).
 *   Resampled reads go through GDAL's default block path.
 * - CreateCopy (gdal_translate -of VTZ) with MAX_Z_ERROR, LOSSLESS, METHOD, EFFORT, TILE,
 *   THREADS. An integer band's offset/scale becomes the file's value mapping (MAX_Z_ERROR
 *   bounds GDAL's values); Int64/UInt64 are stored as Float64 only when every value is
 *   exact (|v| <= 2^53), else refused; samples a mask band hides (per-dataset, internal
 *   or .msk) are nodata (the band's, or an unused end of the type's range, declared).
 * Threads: the GDAL_NUM_THREADS configuration option (a number or ALL_CPUS, the default)
 * sets the threads of a decode.
 */

#include "gdal_pam.h"
#include "gdal_priv.h"
#include "cpl_minixml.h"
#include "cpl_string.h"
#include "cpl_vsi.h"
#include "ogr_spatialref.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <limits>
#include <cstring>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <new>
#include <string>
#include <vector>

#include "vtz.h"

namespace
{

const GByte kMagic[8] = {0x89, 'V', 'T', 'Z', '\r', '\n', 0x1a, '\n'};

/// Report the last vtz error of this thread as a GDAL error.
void ReportVtzError(const char *pszWhat = nullptr)
{
    const char *pszMsg = vtz_last_error();
    if (pszMsg == nullptr || pszMsg[0] == '\0')
        pszMsg = "unknown error";
    if (pszWhat)
        CPLError(CE_Failure, CPLE_AppDefined, "vtz: %s: %s", pszWhat, pszMsg);
    else
        CPLError(CE_Failure, CPLE_AppDefined, "vtz: %s", pszMsg);
}

bool VtzToGDALType(int32_t nType, GDALDataType *peType)
{
    switch (nType)
    {
        case VTZ_U8: *peType = GDT_Byte; return true;
        case VTZ_I16: *peType = GDT_Int16; return true;
        case VTZ_U16: *peType = GDT_UInt16; return true;
        case VTZ_I32: *peType = GDT_Int32; return true;
        case VTZ_F32: *peType = GDT_Float32; return true;
        case VTZ_F64: *peType = GDT_Float64; return true;
        default: return false;
    }
}

int GDALToVtzType(GDALDataType eType)
{
    switch (eType)
    {
        case GDT_Byte: return VTZ_U8;
        case GDT_Int16: return VTZ_I16;
        case GDT_UInt16: return VTZ_U16;
        case GDT_Int32: return VTZ_I32;
        case GDT_Float32: return VTZ_F32;
        case GDT_Float64: return VTZ_F64;
        default: return -1;
    }
}

/// Threads for a decode, from GDAL_NUM_THREADS (0 = all the machine offers).
uint32_t DecodeThreads()
{
    const char *pszThreads = CPLGetConfigOption("GDAL_NUM_THREADS", "ALL_CPUS");
    if (EQUAL(pszThreads, "ALL_CPUS"))
        return 0;
    const int n = atoi(pszThreads);
    return n > 0 ? static_cast<uint32_t>(n) : 1;
}

/// A text the C ABI gives with the two-call pattern (size, then copy); empty when none.
template <class F> std::string TwoCallText(F fn)
{
    const size_t nNeed = fn(nullptr, 0);
    if (nNeed <= 1)
        return std::string();
    std::string osBuf(nNeed, '\0');
    if (fn(&osBuf[0], nNeed) != nNeed)
        return std::string();
    osBuf.resize(strlen(osBuf.c_str()));
    return osBuf;
}

bool IsCopiedDomain(const char *pszDomain)
{
    // Domains that describe the source file, not its values (or that hold a single XML/
    // JSON document, which this driver does not carry).
    return !(EQUAL(pszDomain, "IMAGE_STRUCTURE") ||
             EQUAL(pszDomain, "DERIVED_SUBDATASETS") ||
             EQUAL(pszDomain, "SUBDATASETS") || EQUAL(pszDomain, "RPC") ||
             EQUAL(pszDomain, "GEOLOCATION") ||
             EQUAL(pszDomain, "COLOR_PROFILE") ||
             STARTS_WITH_CI(pszDomain, "xml:") ||
             STARTS_WITH_CI(pszDomain, "json:"));
}

/// What the VTZ reader callbacks hold: GDAL's handle of the file, behind a lock (a
/// VSILFILE is not thread-safe; vtz calls read_ranges one call at a time per handle, from
/// the decode's pool threads, and the lock keeps that true whatever the caller does).
struct VSIReader
{
    VSILFILE *fp = nullptr;
    std::mutex oMutex{};
    // The file system serves VSIFReadMultiRangeL with exact range requests (/vsicurl/,
    // /vsis3/, ...: VSIHasOptimizedReadMultiRange).
    bool bMultiRange = false;
    // While vtz_open_reader runs (the header and the tile index).
    bool bOpening = true;
    // Network files: the ranges fetched last (tile blocks), by offset, up to
    // nCacheMax bytes, the oldest dropped first. A tile's decode reads its neighbours'
    // blocks too (they blend across the margins), so reading a raster block by block
    // (gdalinfo -stats, a reduced read) reads each block up to 9 times: from here
    // after the first.
    std::map<vsi_l_offset, std::vector<GByte>> oCache{};
    std::deque<vsi_l_offset> oCacheOrder{};
    size_t nCached = 0;
    size_t nCacheMax = 0;

    /// The cached bytes holding [nOffset, nOffset + nSize), or nullptr.
    const GByte *Cached(vsi_l_offset nOffset, size_t nSize) const
    {
        auto it = oCache.upper_bound(nOffset);
        if (it == oCache.begin())
            return nullptr;
        --it;
        if (it->first + it->second.size() < nOffset + nSize)
            return nullptr;
        return it->second.data() + (nOffset - it->first);
    }

    void Keep(vsi_l_offset nOffset, const GByte *pabyData, size_t nSize)
    {
        if (nSize > nCacheMax / 4 || Cached(nOffset, nSize) != nullptr)
            return;
        auto it = oCache.find(nOffset);
        if (it != oCache.end())
        {
            nCached -= it->second.size();
            oCache.erase(it);
        }
        oCache[nOffset].assign(pabyData, pabyData + nSize);
        oCacheOrder.push_back(nOffset);
        nCached += nSize;
        while (nCached > nCacheMax && !oCacheOrder.empty())
        {
            auto old = oCache.find(oCacheOrder.front());
            oCacheOrder.pop_front();
            if (old != oCache.end())
            {
                nCached -= old->second.size();
                oCache.erase(old);
            }
        }
    }
};

/// VtzReader::read_ranges. Local files: a seek and a read per range. Network files
/// (VSIHasOptimizedReadMultiRange): the reads of the open (header, tile index) go through
/// the file system's own cache (a seek and a read: GDAL's /vsicurl/ fetches them in
/// CPL_VSIL_CURL_CHUNK_SIZE chunks it keeps, so opening the same file again, as
/// gdal_translate's VRT and QGIS do, fetches nothing); tile blocks go to
/// VSIFReadMultiRangeL, which fetches exactly the ranges given, all at once (one
/// request per range, in parallel), instead of the chunked reads whose read-ahead doubles
/// on every read that follows the last (tiles lie back to back: a window fetched 4x its
/// blocks that way). A single range is given as two halves, which GDAL merges back into
/// one request: with one range it would take the chunked path.
int32_t VSIReadRanges(void *pUser, size_t n, const uint64_t *panOffsets,
                      const size_t *panSizes, uint8_t *const *papabyBuffers,
                      char *pszMessage, size_t nMessageCap)
{
    VSIReader *psReader = static_cast<VSIReader *>(pUser);
    if (n > static_cast<size_t>(INT_MAX) - 1)
    {
        snprintf(pszMessage, nMessageCap, "%zu ranges in one read", n);
        return 1;
    }
    std::lock_guard<std::mutex> oLock(psReader->oMutex);
    CPLErrorReset();
    CPLPushErrorHandler(CPLQuietErrorHandler);
    int nRet = 0;
    if (!psReader->bMultiRange || psReader->bOpening)
    {
        for (size_t i = 0; i < n && nRet == 0; ++i)
            if (VSIFSeekL(psReader->fp, panOffsets[i], SEEK_SET) != 0 ||
                VSIFReadL(papabyBuffers[i], 1, panSizes[i], psReader->fp) != panSizes[i])
                nRet = -1;
    }
    else
    {
        // The ranges not cached, fetched at once.
        std::vector<void *> apData;
        std::vector<vsi_l_offset> anOffsets;
        std::vector<size_t> anSizes;
        std::vector<size_t> anMissing;
        for (size_t i = 0; i < n; ++i)
        {
            if (const GByte *pabyHit = psReader->Cached(panOffsets[i], panSizes[i]))
            {
                memcpy(papabyBuffers[i], pabyHit, panSizes[i]);
                continue;
            }
            anMissing.push_back(i);
            apData.push_back(papabyBuffers[i]);
            anOffsets.push_back(panOffsets[i]);
            anSizes.push_back(panSizes[i]);
        }
        if (anMissing.size() == 1 && anSizes[0] >= 2)
        {
            const size_t nHalf = anSizes[0] / 2;
            apData.push_back(static_cast<GByte *>(apData[0]) + nHalf);
            anOffsets.push_back(anOffsets[0] + nHalf);
            anSizes.push_back(anSizes[0] - nHalf);
            anSizes[0] = nHalf;
        }
        if (!apData.empty())
            nRet = VSIFReadMultiRangeL(static_cast<int>(apData.size()), apData.data(),
                                       anOffsets.data(), anSizes.data(), psReader->fp);
        if (nRet == 0)
            for (size_t i : anMissing)
                psReader->Keep(panOffsets[i], papabyBuffers[i], panSizes[i]);
    }
    CPLPopErrorHandler();
    if (nRet != 0)
    {
        // GDAL's reason (e.g. an HTTP status) when the file system gave one.
        const char *pszWhy = CPLGetLastErrorMsg();
        snprintf(pszMessage, nMessageCap, "%s",
                 pszWhy && pszWhy[0]
                     ? pszWhy
                     : "a short read or an I/O error in GDAL's VSI layer");
        return 1;
    }
    return 0;
}

void VSIReaderClose(void *pUser)
{
    VSIReader *psReader = static_cast<VSIReader *>(pUser);
    if (psReader->fp != nullptr)
        VSIFCloseL(psReader->fp);
    delete psReader;
}

/// vtz_open_reader over GDAL's VSI handle of pszFilename; nullptr after reporting why.
VtzFile *OpenVSIReader(const char *pszFilename)
{
    VSILFILE *fp = VSIFOpenL(pszFilename, "rb");
    if (fp == nullptr)
    {
        CPLError(CE_Failure, CPLE_OpenFailed, "vtz: cannot open %s", pszFilename);
        return nullptr;
    }
    if (VSIFSeekL(fp, 0, SEEK_END) != 0)
    {
        VSIFCloseL(fp);
        CPLError(CE_Failure, CPLE_FileIO, "vtz: cannot measure %s", pszFilename);
        return nullptr;
    }
    VSIReader *psReader = new VSIReader();
    psReader->fp = fp;
    psReader->bMultiRange = VSIHasOptimizedReadMultiRange(pszFilename) != 0;
    // VTZ_REMOTE_CACHE_MB (default 64): the tile blocks a network file's handle keeps.
    const double dfCacheMB =
        CPLAtof(CPLGetConfigOption("VTZ_REMOTE_CACHE_MB", "64"));
    psReader->nCacheMax = static_cast<size_t>(
        std::min(std::max(0.0, dfCacheMB), 1e6) * 1048576.0);
    VtzReader sReader{};
    sReader.user = psReader;
    sReader.length = static_cast<uint64_t>(VSIFTellL(fp));
    sReader.read_ranges = VSIReadRanges;
    sReader.close = VSIReaderClose;
    sReader.name = pszFilename;
    // vtz_open_reader calls VSIReaderClose when it fails, vtz_close when it succeeded.
    VtzFile *hFile = nullptr;
    if (vtz_open_reader(&sReader, nullptr, &hFile) != VTZ_OK || hFile == nullptr)
    {
        ReportVtzError();
        return nullptr;
    }
    // The open read what it keeps (header, index, metadata); from here on, tile blocks.
    std::lock_guard<std::mutex> oLock(psReader->oMutex);
    psReader->bOpening = false;
    return hFile;
}

}  // namespace

/************************************************************************/
/*                            VTZDataset                                */
/************************************************************************/

class VTZRasterBand;

class VTZDataset final : public GDALPamDataset
{
    friend class VTZRasterBand;

    VtzFile *m_hFile = nullptr;
    VtzInfo m_sInfo{};
    // Read over a network (/vsicurl/, /vsis3/, ...: not VSIIsLocal).
    bool m_bRemote = false;
    GDALDataType m_eDT = GDT_Unknown;
    int m_nDTSize = 0;
    OGRSpatialReference m_oSRS{};

    // Version 1: the whole raster of each level (0: full resolution, K: overview K),
    // decoded on the first read of that level.
    std::vector<std::vector<GByte>> m_aabyCache{};
    std::vector<bool> m_abCacheFailed{};
    // Overview levels 1, 2, ... (from the format; empty when VTZ_OVERVIEWS=NO).
    std::vector<std::unique_ptr<VTZRasterBand>> m_apoOverviews{};
    // While gdaladdo builds external overviews, the band shows only those.
    bool m_bBuildingOverviews = false;

    const GByte *EnsureCache(int nLevel);
    CPLErr ReadWindow(int nLevel, int nXOff, int nYOff, int nXSize, int nYSize,
                      void *pData, GDALDataType eBufType, GSpacing nPixelSpace,
                      GSpacing nLineSpace);
    void ApplyGDALMetadata(const char *pszXML);

  public:
    VTZDataset() = default;
    ~VTZDataset() override;

    CPLErr GetGeoTransform(double *padfTransform) override;
#if GDAL_VERSION_NUM >= GDAL_COMPUTE_VERSION(3, 6, 0)
    CPLErr IBuildOverviews(const char *pszResampling, int nOverviews,
                           const int *panOverviewList, int nListBands,
                           const int *panBandList, GDALProgressFunc pfnProgress,
                           void *pProgressData, CSLConstList papszOptions) override
    {
        // GDAL's external overview builder expects the band's overviews to be the .ovr's.
        m_bBuildingOverviews = true;
        const CPLErr eErr = GDALPamDataset::IBuildOverviews(
            pszResampling, nOverviews, panOverviewList, nListBands, panBandList,
            pfnProgress, pProgressData, papszOptions);
        m_bBuildingOverviews = false;
        return eErr;
    }
#endif
    const OGRSpatialReference *GetSpatialRef() const override;

    static int Identify(GDALOpenInfo *poOpenInfo);
    static GDALDataset *Open(GDALOpenInfo *poOpenInfo);
    static GDALDataset *CreateCopy(const char *pszFilename, GDALDataset *poSrcDS,
                                   int bStrict, char **papszOptions,
                                   GDALProgressFunc pfnProgress,
                                   void *pProgressData);
};

/************************************************************************/
/*                           VTZRasterBand                              */
/************************************************************************/

class VTZRasterBand final : public GDALPamRasterBand
{
    friend class VTZDataset;

    // 0: the full-resolution band; K > 0: overview K (every 2^K-th sample).
    int m_nLevel = 0;
    bool m_bHasNoData = false;
    double m_dfNoData = 0.0;
    // From the GDAL metadata (role="unittype" / "offset" / "scale").
    std::string m_osUnitType{};
    bool m_bHasOffset = false, m_bHasScale = false;
    double m_dfOffset = 0.0, m_dfScale = 1.0;

    void FillNoData(void *pImage, size_t nCount) const;
    int CountMissingBlocks(int nTX0, int nTY0, int nTX1, int nTY1);
    CPLErr PrefetchTiles(int nTX0, int nTY0, int nTX1, int nTY1);

  public:
    VTZRasterBand(VTZDataset *poDS, int nBlockX, int nBlockY, int nLevel = 0);
    int GetOverviewCount() override;
    GDALRasterBand *GetOverview(int i) override;

    CPLErr IReadBlock(int nBlockXOff, int nBlockYOff, void *pImage) override;
    CPLErr IRasterIO(GDALRWFlag eRWFlag, int nXOff, int nYOff, int nXSize,
                     int nYSize, void *pData, int nBufXSize, int nBufYSize,
                     GDALDataType eBufType, GSpacing nPixelSpace,
                     GSpacing nLineSpace,
                     GDALRasterIOExtraArg *psExtraArg) override;

    // The file's values come first; PAM (.aux.xml) fills what the file lacks.
    double GetNoDataValue(int *pbSuccess = nullptr) override;
    const char *GetUnitType() override;
    GDALColorInterp GetColorInterpretation() override
    {
        return GCI_GrayIndex;
    }
    double GetOffset(int *pbSuccess = nullptr) override;
    double GetScale(int *pbSuccess = nullptr) override;
};

VTZRasterBand::VTZRasterBand(VTZDataset *poDSIn, int nBlockX, int nBlockY,
                             int nLevel)
    : m_nLevel(nLevel)
{
    poDS = poDSIn;
    nBand = 1;
    // Overview K has ceil(size / 2^K) samples each way.
    nRasterXSize = static_cast<int>(
        (poDSIn->m_sInfo.width + (uint64_t{1} << nLevel) - 1) >> nLevel);
    nRasterYSize = static_cast<int>(
        (poDSIn->m_sInfo.height + (uint64_t{1} << nLevel) - 1) >> nLevel);
    eDataType = poDSIn->m_eDT;
    nBlockXSize = nBlockX;
    nBlockYSize = nBlockY;
    if (poDSIn->m_sInfo.has_nodata)
    {
        m_bHasNoData = true;
        // As the band stores it: the value, or its code when the band holds codes.
        m_dfNoData = poDSIn->m_sInfo.value_nodata;
    }
    if (poDSIn->m_sInfo.has_offset_scale)
    {
        // Codes with the file's value mapping as the band's offset and scale (a GDAL
        // scale/offset of the metadata applies after it: ApplyGDALMetadata).
        m_bHasOffset = m_bHasScale = true;
        m_dfOffset = poDSIn->m_sInfo.value_offset;
        m_dfScale = poDSIn->m_sInfo.value_scale;
    }
}

/// External overviews (.ovr, gdaladdo) when there are, else the format's own levels.
int VTZRasterBand::GetOverviewCount()
{
    if (m_nLevel > 0)
        return 0;
    const int nExternal = GDALPamRasterBand::GetOverviewCount();
    if (nExternal > 0 || static_cast<VTZDataset *>(poDS)->m_bBuildingOverviews)
        return nExternal;
    return static_cast<int>(
        static_cast<VTZDataset *>(poDS)->m_apoOverviews.size());
}

GDALRasterBand *VTZRasterBand::GetOverview(int i)
{
    if (m_nLevel > 0)
        return nullptr;
    if (GDALPamRasterBand::GetOverviewCount() > 0 ||
        static_cast<VTZDataset *>(poDS)->m_bBuildingOverviews)
        return GDALPamRasterBand::GetOverview(i);
    const auto &apoOv = static_cast<VTZDataset *>(poDS)->m_apoOverviews;
    return i >= 0 && i < static_cast<int>(apoOv.size()) ? apoOv[i].get() : nullptr;
}

/// Fill `nCount` samples of the band's type with nodata (0 without one).
void VTZRasterBand::FillNoData(void *pImage, size_t nCount) const
{
    const double dfFill = m_bHasNoData ? m_dfNoData : 0.0;
    GDALCopyWords64(&dfFill, GDT_Float64, 0, pImage, eDataType,
                    GDALGetDataTypeSizeBytes(eDataType),
                    static_cast<GPtrDiff_t>(nCount));
}

CPLErr VTZRasterBand::IReadBlock(int nBlockXOff, int nBlockYOff, void *pImage)
{
    VTZDataset *poGDS = static_cast<VTZDataset *>(poDS);
    const int nDTSize = poGDS->m_nDTSize;
    const int nX0 = nBlockXOff * nBlockXSize;
    const int nY0 = nBlockYOff * nBlockYSize;
    const int nW = std::min(nBlockXSize, nRasterXSize - nX0);
    const int nH = std::min(nBlockYSize, nRasterYSize - nY0);
    const size_t nBlockSamples =
        static_cast<size_t>(nBlockXSize) * static_cast<size_t>(nBlockYSize);

    if (nW < nBlockXSize || nH < nBlockYSize)
        FillNoData(pImage, nBlockSamples);

    if (!poGDS->m_sInfo.tiled)
    {
        // A strip of full rows out of the whole-level cache.
        const GByte *pabyCache = poGDS->EnsureCache(m_nLevel);
        if (pabyCache == nullptr)
            return CE_Failure;
        memcpy(pImage,
               pabyCache + static_cast<size_t>(nY0) * nRasterXSize * nDTSize,
               static_cast<size_t>(nH) * nRasterXSize * nDTSize);
        return CE_None;
    }

    // One tile: decode exactly its samples (a full-width block straight into pImage).
    return poGDS->ReadWindow(m_nLevel, nX0, nY0, nW, nH, pImage, eDataType, nDTSize,
                             static_cast<GSpacing>(nBlockXSize) * nDTSize);
}

CPLErr VTZRasterBand::IRasterIO(GDALRWFlag eRWFlag, int nXOff, int nYOff,
                                int nXSize, int nYSize, void *pData,
                                int nBufXSize, int nBufYSize,
                                GDALDataType eBufType, GSpacing nPixelSpace,
                                GSpacing nLineSpace,
                                GDALRasterIOExtraArg *psExtraArg)
{
    VTZDataset *poGDS = static_cast<VTZDataset *>(poDS);
    if (eRWFlag != GF_Read || nXSize <= 0 || nYSize <= 0)
        return GDALPamRasterBand::IRasterIO(
            eRWFlag, nXOff, nYOff, nXSize, nYSize, pData, nBufXSize, nBufYSize,
            eBufType, nPixelSpace, nLineSpace, psExtraArg);
    const bool bFullRes = nXSize == nBufXSize && nYSize == nBufYSize;
    // A reduced read with overviews (external .ovr from gdaladdo): the base class picks
    // the overview, as for every GDAL driver, instead of decoding full-resolution tiles.
    if (!bFullRes && GetOverviewCount() > 0)
        return GDALPamRasterBand::IRasterIO(
            eRWFlag, nXOff, nYOff, nXSize, nYSize, pData, nBufXSize, nBufYSize,
            eBufType, nPixelSpace, nLineSpace, psExtraArg);

    if (!poGDS->m_sInfo.tiled)
    {
        // Version 1: a full-resolution window is a copy out of the whole-raster cache;
        // a resampled one goes through the blocks (served from the same cache).
        if (!bFullRes)
            return GDALPamRasterBand::IRasterIO(
                eRWFlag, nXOff, nYOff, nXSize, nYSize, pData, nBufXSize,
                nBufYSize, eBufType, nPixelSpace, nLineSpace, psExtraArg);
        const GByte *pabyCache = poGDS->EnsureCache(m_nLevel);
        if (pabyCache == nullptr)
            return CE_Failure;
        const int nDTSize = poGDS->m_nDTSize;
        for (int iY = 0; iY < nYSize; ++iY)
        {
            const GByte *pabySrc =
                pabyCache +
                (static_cast<size_t>(nYOff + iY) * nRasterXSize + nXOff) * nDTSize;
            GDALCopyWords64(pabySrc, eDataType, nDTSize,
                            static_cast<GByte *>(pData) + iY * nLineSpace,
                            eBufType, static_cast<int>(nPixelSpace), nXSize);
        }
        return CE_None;
    }

    // Version 2. A decode pays for the rows and columns it needs (plus the margins tiles
    // are blended over), so a window much smaller than its tiles is cheapest decoded
    // exactly, and several tiles are cheapest decoded together (in parallel, their
    // shared margins once):
    // - every touched block cached: served from the blocks (default path);
    // - a full-resolution window under 1/4 of its tiles' area, or one whose tiles do not
    //   fit in a quarter of the block cache: one vtz_read of exactly the window,
    //   straight into the caller's buffer (not cached);
    // - else (resampled reads too) the missing tiles, when they fit in a quarter of the
    //   block cache, decode in one vtz_read into the cache, and the default path reads
    //   the window out of the blocks (tile by tile through IReadBlock when they do not
    //   fit).
    const int nTX0 = nXOff / nBlockXSize;
    const int nTX1 = (nXOff + nXSize - 1) / nBlockXSize;
    const int nTY0 = nYOff / nBlockYSize;
    const int nTY1 = (nYOff + nYSize - 1) / nBlockYSize;
    if (CountMissingBlocks(nTX0, nTY0, nTX1, nTY1) > 0)
    {
        const GIntBig nTileSamples = static_cast<GIntBig>(nBlockXSize) *
                                     nBlockYSize * (nTX1 - nTX0 + 1) *
                                     (nTY1 - nTY0 + 1);
        const GIntBig nWindowSamples = static_cast<GIntBig>(nXSize) * nYSize;
        const bool bFits =
            nTileSamples * poGDS->m_nDTSize <= GDALGetCacheMax64() / 4;
        // A network file (not VSIIsLocal): the blocks of a window's tiles need their
        // neighbours too (they blend across the margins), the window alone only the tiles
        // it touches (a 256 x 256 window: 4 tiles instead of 16), and every tile is a
        // request; so a window that is not a full-width swath is decoded exactly.
        const bool bExactRemote =
            poGDS->m_bRemote && !(nXOff == 0 && nXSize == nRasterXSize);
        if (bFullRes && (nWindowSamples * 4 <= nTileSamples || !bFits || bExactRemote))
            return poGDS->ReadWindow(m_nLevel, nXOff, nYOff, nXSize, nYSize,
                                     pData, eBufType, nPixelSpace, nLineSpace);
        // Read-ahead: a full-width, full-resolution read is a whole-raster copy's
        // swath (gdal_translate); decoding the following tile rows with it, as many as
        // a quarter of the block cache holds, saves re-decoding the margins between
        // swaths (tiled SRTM1 tile: 1.7 s -> 1.1 s). VTZ_READ_AHEAD=NO turns it off.
        int nReadTY1 = nTY1;
        if (bFullRes && bFits && nXOff == 0 && nXSize == nRasterXSize &&
            CPLTestBool(CPLGetConfigOption("VTZ_READ_AHEAD", "YES")))
        {
            // (nBlocksPerRow/Column are set only once a block was accessed.)
            const int nTileCols = DIV_ROUND_UP(nRasterXSize, nBlockXSize);
            const int nTileRows = DIV_ROUND_UP(nRasterYSize, nBlockYSize);
            const GIntBig nTileRowBytes = static_cast<GIntBig>(nBlockXSize) *
                                          nBlockYSize * nTileCols *
                                          poGDS->m_nDTSize;
            const GIntBig nRows = GDALGetCacheMax64() / 4 / nTileRowBytes;
            nReadTY1 = static_cast<int>(std::min<GIntBig>(
                nTileRows - 1, std::max<GIntBig>(nTY1, nTY0 + nRows - 1)));
        }
        if (bFits && PrefetchTiles(nTX0, nTY0, nTX1, nReadTY1) != CE_None)
            return CE_Failure;
    }
    return GDALPamRasterBand::IRasterIO(eRWFlag, nXOff, nYOff, nXSize, nYSize,
                                        pData, nBufXSize, nBufYSize, eBufType,
                                        nPixelSpace, nLineSpace, psExtraArg);
}

/// How many blocks of [nTX0, nTX1] × [nTY0, nTY1] are not in GDAL's block cache.
int VTZRasterBand::CountMissingBlocks(int nTX0, int nTY0, int nTX1, int nTY1)
{
    int nMissing = 0;
    for (int iTY = nTY0; iTY <= nTY1; ++iTY)
        for (int iTX = nTX0; iTX <= nTX1; ++iTX)
        {
            if (GDALRasterBlock *poBlock = TryGetLockedBlockRef(iTX, iTY))
                poBlock->DropLock();
            else
                ++nMissing;
        }
    return nMissing;
}

/// Decode the tiles of [nTX0, nTX1] × [nTY0, nTY1] not yet in GDAL's block cache with
/// one vtz_read of their bounding box (its tiles decode in parallel) and store them as
/// blocks. One missing tile is left to IReadBlock.
CPLErr VTZRasterBand::PrefetchTiles(int nTX0, int nTY0, int nTX1, int nTY1)
{
    VTZDataset *poGDS = static_cast<VTZDataset *>(poDS);
    int nMissing = 0;
    int nBX0 = nTX1, nBY0 = nTY1, nBX1 = nTX0, nBY1 = nTY0;
    for (int iTY = nTY0; iTY <= nTY1; ++iTY)
        for (int iTX = nTX0; iTX <= nTX1; ++iTX)
        {
            if (GDALRasterBlock *poBlock = TryGetLockedBlockRef(iTX, iTY))
            {
                poBlock->DropLock();
                continue;
            }
            ++nMissing;
            nBX0 = std::min(nBX0, iTX);
            nBY0 = std::min(nBY0, iTY);
            nBX1 = std::max(nBX1, iTX);
            nBY1 = std::max(nBY1, iTY);
        }
    if (nMissing < 2)
        return CE_None;

    const int nDTSize = poGDS->m_nDTSize;
    const int nX0 = nBX0 * nBlockXSize;
    const int nY0 = nBY0 * nBlockYSize;
    const int nW = std::min((nBX1 + 1) * nBlockXSize, nRasterXSize) - nX0;
    const int nH = std::min((nBY1 + 1) * nBlockYSize, nRasterYSize) - nY0;
    GByte *pabyBuf = static_cast<GByte *>(
        VSI_MALLOC3_VERBOSE(nW, nH, nDTSize));
    if (pabyBuf == nullptr)
        return CE_Failure;
    if (poGDS->ReadWindow(m_nLevel, nX0, nY0, nW, nH, pabyBuf, eDataType, nDTSize,
                          static_cast<GSpacing>(nW) * nDTSize) != CE_None)
    {
        VSIFree(pabyBuf);
        return CE_Failure;
    }
    CPLErr eErr = CE_None;
    for (int iTY = nBY0; iTY <= nBY1 && eErr == CE_None; ++iTY)
        for (int iTX = nBX0; iTX <= nBX1; ++iTX)
        {
            if (GDALRasterBlock *poCached = TryGetLockedBlockRef(iTX, iTY))
            {
                poCached->DropLock();
                continue;
            }
            // A new block (not read, not dirty), filled from the decoded box.
            GDALRasterBlock *poBlock = GetLockedBlockRef(iTX, iTY, TRUE);
            if (poBlock == nullptr)
            {
                eErr = CE_Failure;
                break;
            }
            GByte *pabyBlock = static_cast<GByte *>(poBlock->GetDataRef());
            const int nTileX = iTX * nBlockXSize - nX0;
            const int nTileY = iTY * nBlockYSize - nY0;
            const int nTW = std::min(nBlockXSize, nW - nTileX);
            const int nTH = std::min(nBlockYSize, nH - nTileY);
            if (nTW < nBlockXSize || nTH < nBlockYSize)
                FillNoData(pabyBlock, static_cast<size_t>(nBlockXSize) *
                                          nBlockYSize);
            for (int iY = 0; iY < nTH; ++iY)
                memcpy(pabyBlock + static_cast<size_t>(iY) * nBlockXSize * nDTSize,
                       pabyBuf + (static_cast<size_t>(nTileY + iY) * nW + nTileX) *
                                     nDTSize,
                       static_cast<size_t>(nTW) * nDTSize);
            poBlock->DropLock();
        }
    VSIFree(pabyBuf);
    return eErr;
}

double VTZRasterBand::GetNoDataValue(int *pbSuccess)
{
    if (m_bHasNoData)
    {
        if (pbSuccess)
            *pbSuccess = TRUE;
        return m_dfNoData;
    }
    return GDALPamRasterBand::GetNoDataValue(pbSuccess);
}

const char *VTZRasterBand::GetUnitType()
{
    if (!m_osUnitType.empty())
        return m_osUnitType.c_str();
    return GDALPamRasterBand::GetUnitType();
}

double VTZRasterBand::GetOffset(int *pbSuccess)
{
    if (m_bHasOffset)
    {
        if (pbSuccess)
            *pbSuccess = TRUE;
        return m_dfOffset;
    }
    return GDALPamRasterBand::GetOffset(pbSuccess);
}

double VTZRasterBand::GetScale(int *pbSuccess)
{
    if (m_bHasScale)
    {
        if (pbSuccess)
            *pbSuccess = TRUE;
        return m_dfScale;
    }
    return GDALPamRasterBand::GetScale(pbSuccess);
}

/************************************************************************/
/*                         VTZDataset methods                           */
/************************************************************************/

VTZDataset::~VTZDataset()
{
    FlushCache(true);
    m_apoOverviews.clear();
    vtz_close(m_hFile);
}

/// Decode level nLevel of a version-1 file whole, once (0: the full resolution, K:
/// overview K); nullptr after reporting why. A failure is reported again on each call.
const GByte *VTZDataset::EnsureCache(int nLevel)
{
    if (m_aabyCache.size() <= static_cast<size_t>(nLevel))
    {
        m_aabyCache.resize(nLevel + 1);
        m_abCacheFailed.resize(nLevel + 1, false);
    }
    std::vector<GByte> &abyCache = m_aabyCache[nLevel];
    if (!abyCache.empty())
        return abyCache.data();
    if (m_abCacheFailed[nLevel])
    {
        CPLError(CE_Failure, CPLE_AppDefined,
                 "vtz: %s: the raster failed to decode before", GetDescription());
        return nullptr;
    }
    const uint64_t nStep = uint64_t{1} << nLevel;
    const uint32_t nW = static_cast<uint32_t>((m_sInfo.width + nStep - 1) / nStep);
    const uint32_t nH = static_cast<uint32_t>((m_sInfo.height + nStep - 1) / nStep);
    const size_t nBytes = static_cast<size_t>(nW) * nH * m_nDTSize;
    try
    {
        abyCache.resize(nBytes);
    }
    catch (const std::bad_alloc &)
    {
        m_abCacheFailed[nLevel] = true;
        CPLError(CE_Failure, CPLE_OutOfMemory,
                 "vtz: cannot allocate %zu bytes to decode %s", nBytes,
                 GetDescription());
        return nullptr;
    }
    if (nLevel > 0 && !m_aabyCache[0].empty())
    {
        // The full resolution is decoded already: an untiled file's overview is its
        // every 2^K-th sample (spec/FORMAT.md, "Overviews"), so no decode is needed.
        const GByte *pabyFull = m_aabyCache[0].data();
        const size_t nFullW = static_cast<size_t>(m_sInfo.width);
        for (uint32_t iY = 0; iY < nH; ++iY)
            for (uint32_t iX = 0; iX < nW; ++iX)
                memcpy(abyCache.data() + (static_cast<size_t>(iY) * nW + iX) * m_nDTSize,
                       pabyFull + ((static_cast<size_t>(iY) * nStep) * nFullW +
                                   static_cast<size_t>(iX) * nStep) * m_nDTSize,
                       m_nDTSize);
        return abyCache.data();
    }
    CPLDebug("VTZ", "%s: vtz_read of level %d, 0,0 %ux%u (cached whole)",
             GetDescription(), nLevel, nW, nH);
    if (vtz_read_band(m_hFile, static_cast<uint32_t>(nLevel), 0, 0, nW, nH,
                      m_sInfo.value_type, abyCache.data(), nBytes,
                      DecodeThreads()) != VTZ_OK)
    {
        ReportVtzError(GetDescription());
        std::vector<GByte>().swap(abyCache);
        m_abCacheFailed[nLevel] = true;
        return nullptr;
    }
    return abyCache.data();
}

/// Decode the window of level nLevel (0: the full resolution, K: overview K) into
/// pData (samples of eBufType at the given spacings): straight into it when it is a
/// packed buffer of the file's type, else through a scratch buffer.
CPLErr VTZDataset::ReadWindow(int nLevel, int nXOff, int nYOff, int nXSize,
                              int nYSize, void *pData, GDALDataType eBufType,
                              GSpacing nPixelSpace, GSpacing nLineSpace)
{
    const size_t nSamples =
        static_cast<size_t>(nXSize) * static_cast<size_t>(nYSize);
    const size_t nBytes = nSamples * m_nDTSize;
    const bool bDirect =
        eBufType == m_eDT && nPixelSpace == m_nDTSize &&
        nLineSpace == static_cast<GSpacing>(nXSize) * m_nDTSize &&
        reinterpret_cast<uintptr_t>(pData) % m_nDTSize == 0;
    void *pBuf = bDirect ? pData : VSI_MALLOC_VERBOSE(nBytes);
    if (pBuf == nullptr)
        return CE_Failure;
    CPLDebug("VTZ", "%s: vtz_read of level %d, %d,%d %dx%d", GetDescription(),
             nLevel, nXOff, nYOff, nXSize, nYSize);
    const int rc = vtz_read_band(m_hFile, static_cast<uint32_t>(nLevel),
                                 static_cast<uint32_t>(nXOff),
                                 static_cast<uint32_t>(nYOff),
                                 static_cast<uint32_t>(nXSize),
                                 static_cast<uint32_t>(nYSize), m_sInfo.value_type,
                                 pBuf, nBytes, DecodeThreads());
    if (rc != VTZ_OK)
    {
        ReportVtzError(nLevel == 0
                           ? CPLSPrintf("%s: window %d,%d %dx%d", GetDescription(),
                                        nXOff, nYOff, nXSize, nYSize)
                           : CPLSPrintf("%s: overview %d, window %d,%d %dx%d",
                                        GetDescription(), nLevel, nXOff, nYOff,
                                        nXSize, nYSize));
        if (!bDirect)
            VSIFree(pBuf);
        return CE_Failure;
    }
    if (!bDirect)
    {
        for (int iY = 0; iY < nYSize; ++iY)
            GDALCopyWords64(static_cast<GByte *>(pBuf) +
                                static_cast<size_t>(iY) * nXSize * m_nDTSize,
                            m_eDT, m_nDTSize,
                            static_cast<GByte *>(pData) + iY * nLineSpace,
                            eBufType, static_cast<int>(nPixelSpace), nXSize);
        VSIFree(pBuf);
    }
    return CE_None;
}

CPLErr VTZDataset::GetGeoTransform(double *padfTransform)
{
    if (m_sInfo.has_geotransform)
    {
        memcpy(padfTransform, m_sInfo.geotransform, 6 * sizeof(double));
        return CE_None;
    }
    return GDALPamDataset::GetGeoTransform(padfTransform);
}

const OGRSpatialReference *VTZDataset::GetSpatialRef() const
{
    if (!m_oSRS.IsEmpty())
        return &m_oSRS;
    return GDALPamDataset::GetSpatialRef();
}

/// Apply the file's GDAL_METADATA XML the way the GTiff driver applies its tag: items
/// without `sample` are dataset metadata (in their `domain`), items with sample="0" are
/// band 1's, with role description / unittype / offset / scale taken as such.
void VTZDataset::ApplyGDALMetadata(const char *pszXML)
{
    CPLXMLNode *psRoot = nullptr;
    CPLPushErrorHandler(CPLQuietErrorHandler);
    psRoot = CPLParseXMLString(pszXML);
    CPLPopErrorHandler();
    if (psRoot == nullptr || psRoot->eType != CXT_Element ||
        !EQUAL(psRoot->pszValue, "GDALMetadata"))
    {
        CPLError(CE_Warning, CPLE_AppDefined,
                 "vtz: %s: the GDAL metadata is not a <GDALMetadata> document; "
                 "ignored",
                 GetDescription());
        CPLDestroyXMLNode(psRoot);
        return;
    }
    VTZRasterBand *poBand = static_cast<VTZRasterBand *>(GetRasterBand(1));
    bool bMDOffset = false, bMDScale = false;
    double dfMDOffset = 0.0, dfMDScale = 1.0;
    for (CPLXMLNode *psItem = psRoot->psChild; psItem; psItem = psItem->psNext)
    {
        if (psItem->eType != CXT_Element || !EQUAL(psItem->pszValue, "Item"))
            continue;
        const char *pszKey = CPLGetXMLValue(psItem, "name", nullptr);
        const char *pszValue = CPLGetXMLValue(psItem, nullptr, nullptr);
        const char *pszSample = CPLGetXMLValue(psItem, "sample", nullptr);
        const char *pszRole = CPLGetXMLValue(psItem, "role", "");
        const char *pszDomain = CPLGetXMLValue(psItem, "domain", "");
        if (pszKey == nullptr || pszValue == nullptr ||
            EQUAL(pszDomain, "IMAGE_STRUCTURE"))
            continue;
        // GTiff unescapes the (already parsed) value once more; do the same so a
        // file reads here exactly as its GeoTIFF does.
        char *pszText = CPLUnescapeString(pszValue, nullptr, CPLES_XML);
        if (pszSample == nullptr)
        {
            GDALDataset::SetMetadataItem(pszKey, pszText, pszDomain);
        }
        else if (atoi(pszSample) == 0)
        {
            if (EQUAL(pszRole, "description"))
                poBand->GDALRasterBand::SetDescription(pszText);
            else if (EQUAL(pszRole, "unittype"))
                poBand->m_osUnitType = pszText;
            else if (EQUAL(pszRole, "offset"))
            {
                bMDOffset = true;
                dfMDOffset = CPLAtofM(pszText);
            }
            else if (EQUAL(pszRole, "scale"))
            {
                bMDScale = true;
                dfMDScale = CPLAtofM(pszText);
            }
            else if (pszRole[0] == '\0')
                poBand->GDALRasterBand::SetMetadataItem(pszKey, pszText,
                                                        pszDomain);
        }
        // Items of other samples (bands) do not exist in a one-band file: ignored.
        CPLFree(pszText);
    }
    CPLDestroyXMLNode(psRoot);
    // The metadata's offset and scale map the file's values: after the band's own
    // code -> value mapping when it holds codes.
    if (bMDOffset || bMDScale)
    {
        const double dfO1 = poBand->m_bHasOffset ? poBand->m_dfOffset : 0.0;
        const double dfS1 = poBand->m_bHasScale ? poBand->m_dfScale : 1.0;
        poBand->m_bHasOffset = bMDOffset || poBand->m_bHasOffset;
        poBand->m_bHasScale = bMDScale || poBand->m_bHasScale;
        poBand->m_dfOffset = dfMDOffset + dfMDScale * dfO1;
        poBand->m_dfScale = dfMDScale * dfS1;
    }
}

int VTZDataset::Identify(GDALOpenInfo *poOpenInfo)
{
    return poOpenInfo->nHeaderBytes >= 10 &&
           memcmp(poOpenInfo->pabyHeader, kMagic, sizeof(kMagic)) == 0;
}

GDALDataset *VTZDataset::Open(GDALOpenInfo *poOpenInfo)
{
    if (!Identify(poOpenInfo))
        return nullptr;
    const char *pszFilename = poOpenInfo->pszFilename;
    const int nVersion =
        poOpenInfo->pabyHeader[8] | (poOpenInfo->pabyHeader[9] << 8);
    if (nVersion == 3)
    {
        CPLError(CE_Failure, CPLE_NotSupported,
                 "vtz: %s: a vtz point set (format version 3) is not a raster; "
                 "`vtz decode` turns it into points or a gridded raster",
                 pszFilename);
        return nullptr;
    }
    if (poOpenInfo->eAccess == GA_Update)
    {
        CPLError(CE_Failure, CPLE_NotSupported,
                 "vtz: the VTZ driver opens files read-only; write a new file "
                 "with gdal_translate -of VTZ");
        return nullptr;
    }

    // Every path, local or /vsi (in memory, in an archive, on a server: /vsicurl/,
    // /vsis3/, ...), is read by ranges through GDAL's VSI layer: opening reads the
    // header (and a version-2 file's tile index), a window the blocks of its tiles.
    VtzFile *hFile = OpenVSIReader(pszFilename);
    if (hFile == nullptr)
        return nullptr;  // OpenVSIReader reported why.

    auto poDS = std::make_unique<VTZDataset>();
    poDS->m_hFile = hFile;
    poDS->m_bRemote = !VSIIsLocal(pszFilename);
    if (vtz_get_info(hFile, &poDS->m_sInfo) != VTZ_OK)
    {
        ReportVtzError(pszFilename);
        return nullptr;
    }
    const VtzInfo &sInfo = poDS->m_sInfo;
    // The band's type is the values' (or, with an offset and scale, the codes'): the
    // C ABI's one rule (capi/README.md, "Output types").
    if (!VtzToGDALType(sInfo.value_type, &poDS->m_eDT))
    {
        CPLError(CE_Failure, CPLE_NotSupported, "vtz: %s: sample type %d",
                 pszFilename, static_cast<int>(sInfo.value_type));
        return nullptr;
    }
    poDS->m_nDTSize = GDALGetDataTypeSizeBytes(poDS->m_eDT);
    if (sInfo.width > INT_MAX || sInfo.height > INT_MAX ||
        !GDALCheckDatasetDimensions(static_cast<int>(sInfo.width),
                                    static_cast<int>(sInfo.height)))
        return nullptr;
    poDS->nRasterXSize = static_cast<int>(sInfo.width);
    poDS->nRasterYSize = static_cast<int>(sInfo.height);

    int nBlockX, nBlockY;
    if (sInfo.tiled)
    {
        if (sInfo.tile_width == 0 || sInfo.tile_height == 0 ||
            sInfo.tile_width > sInfo.width || sInfo.tile_height > sInfo.height)
        {
            CPLError(CE_Failure, CPLE_AppDefined,
                     "vtz: %s: tile size %ux%u does not fit the raster",
                     pszFilename, sInfo.tile_width, sInfo.tile_height);
            return nullptr;
        }
        nBlockX = static_cast<int>(sInfo.tile_width);
        nBlockY = static_cast<int>(sInfo.tile_height);
    }
    else
    {
        // Strips of about 1 MiB of full rows, served from the whole-raster cache.
        const size_t nRowBytes =
            static_cast<size_t>(poDS->nRasterXSize) * poDS->m_nDTSize;
        nBlockX = poDS->nRasterXSize;
        nBlockY = static_cast<int>(std::max<size_t>(
            1, std::min<size_t>(poDS->nRasterYSize, (1 << 20) / nRowBytes)));
    }
    poDS->SetBand(1, new VTZRasterBand(poDS.get(), nBlockX, nBlockY));
    // The format's own overviews, down to about 64 samples along the longer side.
    if (CPLTestBool(CPLGetConfigOption("VTZ_OVERVIEWS", "YES")))
    {
        for (int nLevel = 1; nLevel <= 30; ++nLevel)
        {
            const uint64_t nStep = uint64_t{1} << nLevel;
            const uint64_t nLong = (std::max(sInfo.width, sInfo.height) + nStep - 1) / nStep;
            if (nLong < 64)
                break;
            const int nOvH = static_cast<int>((sInfo.height + nStep - 1) / nStep);
            const int nOvW = static_cast<int>((sInfo.width + nStep - 1) / nStep);
            int nOvBX, nOvBY;
            if (sInfo.tiled)
            {
                // A tile's core at this level.
                nOvBX = static_cast<int>(std::max<uint64_t>(1, (nBlockX + nStep - 1) / nStep));
                nOvBY = static_cast<int>(std::max<uint64_t>(1, (nBlockY + nStep - 1) / nStep));
            }
            else
            {
                nOvBX = nOvW;
                nOvBY = std::max(1, std::min(nOvH, (1 << 20) / (nOvW * poDS->m_nDTSize)));
            }
            poDS->m_apoOverviews.push_back(std::make_unique<VTZRasterBand>(
                poDS.get(), nOvBX, nOvBY, nLevel));
        }
    }

    // Georeferencing. A CRS text from the file may be anything SetFromUserInput takes:
    // refuse the forms that read files or the network.
    if (sInfo.has_geotransform)
        poDS->GDALDataset::SetMetadataItem(
            "AREA_OR_POINT", sInfo.pixel_is_point ? "Point" : "Area");
    const std::string osCRS = TwoCallText(
        [hFile](char *buf, size_t cap) { return vtz_get_crs(hFile, buf, cap); });
    if (!osCRS.empty())
    {
        poDS->m_oSRS.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
        if (poDS->m_oSRS.SetFromUserInput(
                osCRS.c_str(),
                OGRSpatialReference::SET_FROM_USER_INPUT_LIMITATIONS_get()) !=
            OGRERR_NONE)
        {
            CPLError(CE_Warning, CPLE_AppDefined,
                     "vtz: %s: cannot interpret the CRS '%s'; ignored",
                     pszFilename, osCRS.c_str());
            poDS->m_oSRS.Clear();
        }
    }
    if (sInfo.epsg != 0)
    {
        // The EPSG code's definition from PROJ's database (with its name, usage and
        // datum ensemble, as a GeoTIFF of the same code shows it) when it is the same
        // CRS as the file's text, or the file has none GDAL understands.
        OGRSpatialReference oEPSG;
        oEPSG.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
        CPLPushErrorHandler(CPLQuietErrorHandler);
        const bool bEPSG =
            oEPSG.importFromEPSG(static_cast<int>(sInfo.epsg)) == OGRERR_NONE;
        CPLPopErrorHandler();
        if (bEPSG && (poDS->m_oSRS.IsEmpty() || oEPSG.IsSame(&poDS->m_oSRS)))
            poDS->m_oSRS = oEPSG;
    }
    if (poDS->m_oSRS.IsEmpty() && sInfo.has_geotransform)
    {
        // A CRS the source held only as GeoTIFF keys: the C ABI writes them into a 1 x 1
        // GeoTIFF, and GDAL's GTiff driver reads them back exactly as from the source.
        const size_t nTiff = vtz_get_georef_geotiff(hFile, nullptr, 0);
        if (nTiff > 0)
        {
            std::vector<GByte> abyTiff(nTiff);
            vtz_get_georef_geotiff(hFile, abyTiff.data(), abyTiff.size());
            const std::string osMem =
                CPLSPrintf("/vsimem/vtz_georef_%p.tif", static_cast<void *>(poDS.get()));
            VSILFILE *fp = VSIFileFromMemBuffer(osMem.c_str(), abyTiff.data(),
                                                abyTiff.size(), FALSE);
            if (fp != nullptr)
            {
                VSIFCloseL(fp);
                const char *const apszDrivers[] = {"GTiff", nullptr};
                GDALDataset *poTiff = GDALDataset::FromHandle(GDALOpenEx(
                    osMem.c_str(), GDAL_OF_RASTER | GDAL_OF_INTERNAL, apszDrivers,
                    nullptr, nullptr));
                if (poTiff != nullptr)
                {
                    if (const OGRSpatialReference *poSRS = poTiff->GetSpatialRef())
                        poDS->m_oSRS = *poSRS;
                    GDALClose(poTiff);
                }
                VSIUnlink(osMem.c_str());
            }
        }
    }

    const std::string osMD =
        TwoCallText([hFile](char *buf, size_t cap)
                    { return vtz_get_gdal_metadata(hFile, buf, cap); });
    if (!osMD.empty())
        poDS->ApplyGDALMetadata(osMD.c_str());

    // How the file is coded, where GTiff reports LERC's.
    poDS->GDALDataset::SetMetadataItem("COMPRESSION", "VTZ", "IMAGE_STRUCTURE");
    poDS->GDALDataset::SetMetadataItem(
        "MAX_Z_ERROR", CPLSPrintf("%.17g", sInfo.max_error), "IMAGE_STRUCTURE");
    poDS->GDALDataset::SetMetadataItem(
        "VTZ_TILED", sInfo.tiled ? "YES" : "NO", "IMAGE_STRUCTURE");
    poDS->GDALDataset::SetMetadataItem("VTZ_VERSION", CPLSPrintf("%d", nVersion),
                                       "IMAGE_STRUCTURE");

    // PAM (.aux.xml) and external overviews (.ovr).
    poDS->SetDescription(pszFilename);
    poDS->TryLoadXML(poOpenInfo->GetSiblingFiles());
    poDS->oOvManager.Initialize(poDS.get(), pszFilename,
                                poOpenInfo->GetSiblingFiles());
    return poDS.release();
}

/************************************************************************/
/*                              CreateCopy                              */
/************************************************************************/

namespace
{

void AppendItem(CPLXMLNode *psRoot, const char *pszKey, const char *pszValue,
                bool bBand, const char *pszRole, const char *pszDomain)
{
    CPLXMLNode *psItem = CPLCreateXMLNode(nullptr, CXT_Element, "Item");
    CPLAddXMLAttributeAndValue(psItem, "name", pszKey);
    if (bBand)
        CPLAddXMLAttributeAndValue(psItem, "sample", "0");
    if (pszRole)
        CPLAddXMLAttributeAndValue(psItem, "role", pszRole);
    if (pszDomain && pszDomain[0])
        CPLAddXMLAttributeAndValue(psItem, "domain", pszDomain);
    // Escaped here and again when serialized, as GTiff writes its GDAL_METADATA tag (its
    // reader, and ApplyGDALMetadata, unescape twice).
    char *pszEscaped = CPLEscapeString(pszValue, -1, CPLES_XML);
    CPLCreateXMLNode(psItem, CXT_Text, pszEscaped);
    CPLFree(pszEscaped);
    CPLAddXMLChild(psRoot, psItem);
}

/// The metadata items of every copied domain of an object (AREA_OR_POINT excluded: the
/// file carries it as pixel_is_point).
void AppendMetadata(CPLXMLNode *psRoot, GDALMajorObject *poObj, bool bBand)
{
    char **papszDomains = poObj->GetMetadataDomainList();
    // The default domain first, then the others in their order.
    CPLStringList aosDomains;
    aosDomains.AddString("");
    for (char **p = papszDomains; p && *p; ++p)
        if ((*p)[0] != '\0' && IsCopiedDomain(*p))
            aosDomains.AddString(*p);
    CSLDestroy(papszDomains);
    for (int i = 0; i < aosDomains.size(); ++i)
    {
        const char *pszDomain = aosDomains[i];
        char **papszMD = poObj->GetMetadata(pszDomain);
        for (char **p = papszMD; p && *p; ++p)
        {
            char *pszKey = nullptr;
            const char *pszValue = CPLParseNameValue(*p, &pszKey);
            if (pszKey && pszValue &&
                !(pszDomain[0] == '\0' && !bBand &&
                  EQUAL(pszKey, "AREA_OR_POINT")))
                AppendItem(psRoot, pszKey, pszValue, bBand, nullptr, pszDomain);
            CPLFree(pszKey);
        }
    }
}

/// The GDAL_METADATA XML of a dataset and its band 1, as GTiff writes it (empty: none).
std::string BuildGDALMetadata(GDALDataset *poSrcDS, bool bOffsetScale)
{
    CPLXMLNode *psRoot = CPLCreateXMLNode(nullptr, CXT_Element, "GDALMetadata");
    AppendMetadata(psRoot, poSrcDS, false);
    GDALRasterBand *poBand = poSrcDS->GetRasterBand(1);
    AppendMetadata(psRoot, poBand, true);
    int bHas = FALSE;
    const double dfOffset = poBand->GetOffset(&bHas);
    if (bOffsetScale && bHas && dfOffset != 0.0)
        AppendItem(psRoot, "OFFSET", CPLSPrintf("%.17g", dfOffset), true,
                   "offset", nullptr);
    bHas = FALSE;
    const double dfScale = poBand->GetScale(&bHas);
    if (bOffsetScale && bHas && dfScale != 1.0)
        AppendItem(psRoot, "SCALE", CPLSPrintf("%.17g", dfScale), true, "scale",
                   nullptr);
    const char *pszUnit = poBand->GetUnitType();
    if (pszUnit && pszUnit[0])
        AppendItem(psRoot, "UNITTYPE", pszUnit, true, "unittype", nullptr);
    const char *pszDesc = poBand->GetDescription();
    if (pszDesc && pszDesc[0])
        AppendItem(psRoot, "DESCRIPTION", pszDesc, true, "description", nullptr);
    std::string osXML;
    if (psRoot->psChild)
    {
        char *pszXML = CPLSerializeXMLTree(psRoot);
        osXML = pszXML;
        CPLFree(pszXML);
    }
    CPLDestroyXMLNode(psRoot);
    return osXML;
}

/// A creation option that must be an integer within [nMin, nMax].
bool IntOption(char **papszOptions, const char *pszName, int nMin, int nMax,
               int *pnOut)
{
    const char *pszValue = CSLFetchNameValue(papszOptions, pszName);
    if (pszValue == nullptr)
        return true;
    char *pszEnd = nullptr;
    const long n = strtol(pszValue, &pszEnd, 10);
    if (pszEnd == pszValue || *pszEnd != '\0' || n < nMin || n > nMax)
    {
        CPLError(CE_Failure, CPLE_IllegalArg,
                 "vtz: %s=%s is not an integer in %d..%d", pszName, pszValue,
                 nMin, nMax);
        return false;
    }
    *pnOut = static_cast<int>(n);
    return true;
}

/// Fill the encode options from the creation options; false (reported) when one is bad.
bool ParseCreationOptions(char **papszOptions, VtzEncodeOptions *psOpts,
                          std::string *posMethod)
{
    const char *pszMaxErr = CSLFetchNameValue(papszOptions, "MAX_Z_ERROR");
    const char *pszLossless = CSLFetchNameValue(papszOptions, "LOSSLESS");
    const bool bLossless =
        pszLossless ? CPLTestBool(pszLossless) : pszMaxErr == nullptr;
    if (bLossless && pszMaxErr)
    {
        CPLError(CE_Failure, CPLE_IllegalArg,
                 "vtz: LOSSLESS=YES and MAX_Z_ERROR=%s contradict each other",
                 pszMaxErr);
        return false;
    }
    if (!bLossless && pszMaxErr == nullptr)
    {
        CPLError(CE_Failure, CPLE_IllegalArg,
                 "vtz: LOSSLESS=NO needs a MAX_Z_ERROR (data units, or N%%)");
        return false;
    }
    if (pszMaxErr)
    {
        std::string osValue(pszMaxErr);
        if (!osValue.empty() && osValue.back() == '%')
        {
            psOpts->max_error_percent = 1;
            osValue.pop_back();
        }
        char *pszEnd = nullptr;
        const double dfErr = CPLStrtod(osValue.c_str(), &pszEnd);
        if (osValue.empty() || *pszEnd != '\0' || !(dfErr >= 0) ||
            !std::isfinite(dfErr))
        {
            CPLError(CE_Failure, CPLE_IllegalArg,
                     "vtz: MAX_Z_ERROR=%s is not a bound >= 0 (data units, or "
                     "N%%)",
                     pszMaxErr);
            return false;
        }
        psOpts->max_error = dfErr;
    }

    if (const char *pszMethod = CSLFetchNameValue(papszOptions, "METHOD"))
        *posMethod = pszMethod;
    int nEffort = 0;
    if (!IntOption(papszOptions, "EFFORT", 1, 9, &nEffort))
        return false;
    psOpts->effort = nEffort;

    const char *pszTile = CSLFetchNameValue(papszOptions, "TILE");
    if (pszTile && (EQUAL(pszTile, "NONE") || EQUAL(pszTile, "NO")))
        psOpts->tile = -1;
    else if (pszTile && !EQUAL(pszTile, "DEFAULT"))
    {
        int nTile = 0;
        if (!IntOption(papszOptions, "TILE", 64, INT_MAX, &nTile))
            return false;
        psOpts->tile = nTile;
    }

    const char *pszThreads = CSLFetchNameValue(papszOptions, "THREADS");
    if (pszThreads == nullptr)
        pszThreads = CPLGetConfigOption("GDAL_NUM_THREADS", "ALL_CPUS");
    if (EQUAL(pszThreads, "ALL_CPUS"))
        psOpts->threads = 0;
    else
    {
        char *pszEnd = nullptr;
        const long n = strtol(pszThreads, &pszEnd, 10);
        if (pszEnd == pszThreads || *pszEnd != '\0' || n < 1 || n > 65536)
        {
            CPLError(CE_Failure, CPLE_IllegalArg,
                     "vtz: THREADS=%s is not a count >= 1 or ALL_CPUS",
                     pszThreads);
            return false;
        }
        psOpts->threads = static_cast<uint32_t>(n);
    }
    return true;
}

}  // namespace

GDALDataset *VTZDataset::CreateCopy(const char *pszFilename, GDALDataset *poSrcDS,
                                    int bStrict, char **papszOptions,
                                    GDALProgressFunc pfnProgress,
                                    void *pProgressData)
{
    if (pfnProgress == nullptr)
        pfnProgress = GDALDummyProgress;
    if (poSrcDS->GetRasterCount() != 1)
    {
        CPLError(CE_Failure, CPLE_NotSupported,
                 "vtz: a .vtz raster holds one band; the source has %d (pick one "
                 "with gdal_translate -b N)",
                 poSrcDS->GetRasterCount());
        return nullptr;
    }
    GDALRasterBand *poBand = poSrcDS->GetRasterBand(1);
    GDALDataType eDT = poBand->GetRasterDataType();
    // 64-bit integers are stored as Float64, which holds them exactly only within
    // +-2^53: the band is read as it is and refused when a value is beyond (below).
    bool b64 = false;
#if GDAL_VERSION_NUM >= GDAL_COMPUTE_VERSION(3, 5, 0)
    b64 = eDT == GDT_Int64 || eDT == GDT_UInt64;
#endif
    const GDALDataType eSrcDT = eDT;
    if (GDALToVtzType(eDT) < 0)
    {
        if (bStrict || GDALDataTypeIsComplex(eDT))
        {
            CPLError(CE_Failure, CPLE_NotSupported,
                     "vtz: data type %s is not one vtz stores (Byte, Int16, "
                     "UInt16, Int32, Float32, Float64)",
                     GDALGetDataTypeName(eDT));
            return nullptr;
        }
        CPLError(CE_Warning, CPLE_AppDefined,
                 "vtz: data type %s stored as Float64", GDALGetDataTypeName(eDT));
        eDT = GDT_Float64;
    }

    VtzEncodeOptions sOpts = vtz_encode_options_init();
    std::string osMethod;
    if (!ParseCreationOptions(papszOptions, &sOpts, &osMethod))
        return nullptr;
    if (!osMethod.empty())
        sOpts.method = osMethod.c_str();

    // Georeferencing, nodata, metadata.
    double adfGT[6];
    if (poSrcDS->GetGeoTransform(adfGT) == CE_None)
    {
        sOpts.has_geotransform = 1;
        memcpy(sOpts.geotransform, adfGT, sizeof(adfGT));
        const char *pszAoP = poSrcDS->GetMetadataItem("AREA_OR_POINT");
        sOpts.pixel_is_point = pszAoP && EQUAL(pszAoP, "Point");
    }
    std::string osWKT;
    if (const OGRSpatialReference *poSRS = poSrcDS->GetSpatialRef())
    {
        // An EPSG code alone when the CRS is exactly that code's; else the WKT (WKT1
        // when it can hold the CRS, else WKT2), with the code when one is known.
        OGRSpatialReference oSRS(*poSRS);
        if (oSRS.GetAuthorityName(nullptr) == nullptr)
            oSRS.AutoIdentifyEPSG();
        const char *pszAuth = oSRS.GetAuthorityName(nullptr);
        const char *pszCode = oSRS.GetAuthorityCode(nullptr);
        bool bCodeOnly = false;
        if (pszAuth && pszCode && EQUAL(pszAuth, "EPSG"))
        {
            sOpts.epsg = static_cast<uint32_t>(atoi(pszCode));
            OGRSpatialReference oRef;
            bCodeOnly = oRef.importFromEPSG(static_cast<int>(sOpts.epsg)) ==
                            OGRERR_NONE &&
                        oRef.IsSame(poSRS);
        }
        if (!bCodeOnly)
        {
            char *pszWKT = nullptr;
            const char *apszWKT1[] = {"FORMAT=WKT1", nullptr};
            const char *apszWKT2[] = {"FORMAT=WKT2_2019", nullptr};
            CPLPushErrorHandler(CPLQuietErrorHandler);
            if (poSRS->exportToWkt(&pszWKT, apszWKT1) != OGRERR_NONE)
            {
                CPLFree(pszWKT);
                pszWKT = nullptr;
                poSRS->exportToWkt(&pszWKT, apszWKT2);
            }
            CPLPopErrorHandler();
            if (pszWKT)
                osWKT = pszWKT;
            CPLFree(pszWKT);
            if (!osWKT.empty())
                sOpts.crs_wkt = osWKT.c_str();
        }
    }
    int bHasNoData = FALSE;
    const double dfNoData = poBand->GetNoDataValue(&bHasNoData);
    if (bHasNoData)
    {
        sOpts.has_nodata = 1;
        sOpts.nodata = dfNoData;
    }
    // The band's offset and scale over integer codes are the file's value mapping (its
    // values are GDAL's, and MAX_Z_ERROR bounds them, as `vtz encode` does with a
    // GeoTIFF's scale/offset); over floats they stay GDAL metadata.
    {
        int bHasOffset = FALSE, bHasScale = FALSE;
        const double dfOffset = poBand->GetOffset(&bHasOffset);
        const double dfScale = poBand->GetScale(&bHasScale);
        const bool bCodes = GDALToVtzType(eDT) >= 0 && !GDALDataTypeIsFloating(eDT);
        if (bCodes && ((bHasOffset && dfOffset != 0.0) || (bHasScale && dfScale != 1.0)) &&
            std::isfinite(dfOffset) && std::isfinite(dfScale) && dfScale != 0.0)
        {
            sOpts.has_offset_scale = 1;
            sOpts.value_offset = bHasOffset ? dfOffset : 0.0;
            sOpts.value_scale = bHasScale ? dfScale : 1.0;
        }
    }
    const std::string osMD = BuildGDALMetadata(poSrcDS, !sOpts.has_offset_scale);
    if (!osMD.empty())
        sOpts.gdal_metadata = osMD.c_str();

    // Read the band whole (half of the progress), then encode.
    const int nXSize = poSrcDS->GetRasterXSize();
    const int nYSize = poSrcDS->GetRasterYSize();
    const int nDTSize = GDALGetDataTypeSizeBytes(eDT);
    void *pData = VSI_MALLOC3_VERBOSE(nXSize, nYSize, nDTSize);
    if (pData == nullptr)
        return nullptr;
    const size_t nSamples = static_cast<size_t>(nXSize) * static_cast<size_t>(nYSize);
    void *pScaled = GDALCreateScaledProgress(0.0, 0.5, pfnProgress, pProgressData);
    GDALRasterIOExtraArg sExtra;
    INIT_RASTERIO_EXTRA_ARG(sExtra);
    sExtra.pfnProgress = GDALScaledProgress;
    sExtra.pProgressData = pScaled;
    CPLErr eErr;
    if (b64)
    {
        // 64-bit integers, read as they are: each must be exactly a Float64 (|v| <= 2^53),
        // else the file would hold other values than the source's.
        std::vector<GInt64> anRaw;
        try
        {
            anRaw.resize(nSamples);
        }
        catch (const std::bad_alloc &)
        {
            VSIFree(pData);
            CPLError(CE_Failure, CPLE_OutOfMemory, "vtz: cannot read the band");
            return nullptr;
        }
        eErr = poBand->RasterIO(GF_Read, 0, 0, nXSize, nYSize, anRaw.data(), nXSize,
                                nYSize, eSrcDT, 0, 0, &sExtra);
        const double dfExact = 9007199254740992.0;  // 2^53
        for (size_t i = 0; eErr == CE_None && i < nSamples; ++i)
        {
            const bool bUnsigned = eSrcDT != GDT_Int64;
            const uint64_t nU = static_cast<uint64_t>(anRaw[i]);
            const double dfV = bUnsigned ? static_cast<double>(nU)
                                         : static_cast<double>(anRaw[i]);
            if (std::fabs(dfV) > dfExact)
            {
                CPLError(CE_Failure, CPLE_NotSupported,
                         "vtz: %s value %s at row %d, col %d is not exactly a Float64 "
                         "(vtz stores 64-bit integers as Float64, exact only within "
                         "+-2^53)",
                         GDALGetDataTypeName(eSrcDT),
                         bUnsigned ? CPLSPrintf(CPL_FRMT_GUIB, static_cast<GUIntBig>(nU))
                                   : CPLSPrintf(CPL_FRMT_GIB,
                                                static_cast<GIntBig>(anRaw[i])),
                         static_cast<int>(i / nXSize), static_cast<int>(i % nXSize));
                eErr = CE_Failure;
                break;
            }
            static_cast<double *>(pData)[i] = dfV;
        }
    }
    else
    {
        eErr = poBand->RasterIO(GF_Read, 0, 0, nXSize, nYSize, pData, nXSize, nYSize,
                                eDT, 0, 0, &sExtra);
    }
    GDALDestroyScaledProgress(pScaled);
    if (eErr != CE_None)
    {
        VSIFree(pData);
        return nullptr;
    }
    // A mask band of its own (a per-dataset mask, GDAL_TIFF_INTERNAL_MASK or a .msk, or
    // an alpha band): its masked samples are nodata, the band's nodata value or, without
    // one, an end of the type's range that no valid sample holds, declared as nodata (so
    // GDAL derives the same mask from the .vtz; a .vtz header cannot declare NaN).
    const int nMaskFlags = poBand->GetMaskFlags();
    if (!(nMaskFlags & GMF_ALL_VALID) && !(nMaskFlags & GMF_NODATA))
    {
        std::vector<GByte> abyMask;
        std::vector<double> adfValues;
        try
        {
            abyMask.resize(nSamples);
            adfValues.resize(nSamples);
        }
        catch (const std::bad_alloc &)
        {
            VSIFree(pData);
            CPLError(CE_Failure, CPLE_OutOfMemory, "vtz: cannot read the mask band");
            return nullptr;
        }
        if (poBand->GetMaskBand()->RasterIO(GF_Read, 0, 0, nXSize, nYSize,
                                            abyMask.data(), nXSize, nYSize, GDT_Byte,
                                            0, 0, nullptr) != CE_None)
        {
            VSIFree(pData);
            return nullptr;
        }
        GDALCopyWords64(pData, eDT, nDTSize, adfValues.data(), GDT_Float64,
                        sizeof(double), static_cast<GPtrDiff_t>(nSamples));
        size_t nMasked = 0;
        for (size_t i = 0; i < nSamples; ++i)
            nMasked += abyMask[i] == 0;
        double dfFill = dfNoData;
        if (nMasked > 0 && !bHasNoData)
        {
            // As vtz's GeoTIFF writer: the type's lowest value (highest for unsigned
            // types), else the other end, when no valid sample holds it.
            const double dfMin = GDALAdjustValueToDataType(
                eDT, -std::numeric_limits<double>::max(), nullptr, nullptr);
            const double dfMax = GDALAdjustValueToDataType(
                eDT, std::numeric_limits<double>::max(), nullptr, nullptr);
            const bool bUnsigned = dfMin == 0.0;
            const double adfTry[2] = {bUnsigned ? dfMax : dfMin, bUnsigned ? dfMin : dfMax};
            bool bFound = false;
            for (double dfTry : adfTry)
            {
                bool bUsed = false;
                for (size_t i = 0; i < nSamples && !bUsed; ++i)
                    bUsed = abyMask[i] != 0 && adfValues[i] == dfTry;
                if (!bUsed)
                {
                    dfFill = dfTry;
                    bFound = true;
                    break;
                }
            }
            if (!bFound)
            {
                VSIFree(pData);
                CPLError(CE_Failure, CPLE_NotSupported,
                         "vtz: the band has masked samples and no nodata value, and "
                         "valid samples hold both ends of %s: set one with "
                         "gdal_translate -a_nodata",
                         GDALGetDataTypeName(eDT));
                return nullptr;
            }
            sOpts.has_nodata = 1;
            sOpts.nodata = dfFill;
        }
        for (size_t i = 0; i < nSamples; ++i)
            if (abyMask[i] == 0)
                adfValues[i] = dfFill;
        if (nMasked > 0)
            GDALCopyWords64(adfValues.data(), GDT_Float64, sizeof(double), pData, eDT,
                            nDTSize, static_cast<GPtrDiff_t>(nSamples));
        CPLDebug("VTZ", "%s: %zu samples masked by the source's mask band are nodata",
                 pszFilename, nMasked);
    }
    if (!pfnProgress(0.5, "encoding", pProgressData))
    {
        VSIFree(pData);
        CPLError(CE_Failure, CPLE_UserInterrupt, "User terminated");
        return nullptr;
    }
    // The encode reports its fraction done: the second half of GDAL's bar (the C ABI
    // cannot stop an encode, so a cancel here takes effect when it returns).
    struct EncodeProgress
    {
        GDALProgressFunc pfn;
        void *pData;
        bool bCancelled;
    } sProgress{pfnProgress, pProgressData, false};
    sOpts.progress = [](double dfFraction, void *pUser)
    {
        auto *p = static_cast<EncodeProgress *>(pUser);
        if (!p->bCancelled && !p->pfn(0.5 + 0.5 * dfFraction, "encoding", p->pData))
            p->bCancelled = true;
    };
    sOpts.progress_data = &sProgress;

    int rc;
    if (STARTS_WITH(pszFilename, "/vsi"))
    {
        // A /vsi destination: encode in memory, then write through VSI.
        uint8_t *pabyOut = nullptr;
        size_t nOut = 0;
        rc = vtz_encode(pData, GDALToVtzType(eDT), static_cast<uint32_t>(nXSize),
                        static_cast<uint32_t>(nYSize), &sOpts, &pabyOut, &nOut);
        if (rc == VTZ_OK)
        {
            VSILFILE *fp = VSIFOpenL(pszFilename, "wb");
            const bool bOK = fp != nullptr &&
                             VSIFWriteL(pabyOut, 1, nOut, fp) == nOut;
            const bool bClosed = fp == nullptr || VSIFCloseL(fp) == 0;
            vtz_free_bytes(pabyOut, nOut);
            if (!bOK || !bClosed)
            {
                VSIFree(pData);
                CPLError(CE_Failure, CPLE_FileIO, "vtz: cannot write %s",
                         pszFilename);
                return nullptr;
            }
        }
    }
    else
    {
        rc = vtz_encode_to_path(pData, GDALToVtzType(eDT),
                                static_cast<uint32_t>(nXSize),
                                static_cast<uint32_t>(nYSize), &sOpts, pszFilename);
    }
    VSIFree(pData);
    if (rc != VTZ_OK)
    {
        ReportVtzError(pszFilename);
        return nullptr;
    }
    if (sProgress.bCancelled)
    {
        VSIUnlink(pszFilename);
        CPLError(CE_Failure, CPLE_UserInterrupt, "User terminated");
        return nullptr;
    }
    pfnProgress(1.0, "", pProgressData);

    GDALOpenInfo oOpenInfo(pszFilename, GA_ReadOnly);
    return Open(&oOpenInfo);
}

/************************************************************************/
/*                          GDALRegister_VTZ                            */
/************************************************************************/

// Both are exported (the plugin is built with -fvisibility=hidden): GDAL's plugin loader
// looks for GDALRegister_VTZ (from the file name gdal_VTZ.so), then GDALRegisterMe.
extern "C" CPL_DLL void GDALRegister_VTZ();

// vtzzarr.cpp: the "vtz" decompressor of GDAL's Zarr driver.
void VTZRegisterZarrDecompressor();

void GDALRegister_VTZ()
{
    if (!GDAL_CHECK_VERSION("VTZ"))
        return;
    if (GDALGetDriverByName("VTZ") != nullptr)
        return;

    GDALDriver *poDriver = new GDALDriver();
    poDriver->SetDescription("VTZ");
    poDriver->SetMetadataItem(GDAL_DCAP_RASTER, "YES");
    poDriver->SetMetadataItem(GDAL_DMD_LONGNAME, "vtz elevation codec");
    poDriver->SetMetadataItem(GDAL_DMD_EXTENSION, "vtz");
    poDriver->SetMetadataItem(GDAL_DMD_CREATIONDATATYPES,
                              "Byte Int16 UInt16 Int32 Float32 Float64");
    poDriver->SetMetadataItem(GDAL_DCAP_VIRTUALIO, "YES");
    poDriver->SetMetadataItem(
        GDAL_DMD_CREATIONOPTIONLIST,
        "<CreationOptionList>"
        "  <Option name='MAX_Z_ERROR' type='string' description='Bound on every "
        "valid sample: data units, or N% of the value range (lossy)'/>"
        "  <Option name='LOSSLESS' type='boolean' description='Store every sample "
        "exactly (the default when MAX_Z_ERROR is absent)'/>"
        "  <Option name='METHOD' type='string' description='best, residual, "
        "sibson, grid, haar, fis, or a comma list' default='best'/>"
        "  <Option name='EFFORT' type='int' min='1' max='9' description='Encoder "
        "effort: 1-5 the fast-decoding lane coding, 6 the compact coding, 7-9 the "
        "smallest of all' default='5'/>"
        "  <Option name='TILE' type='string' description='Tile side in samples "
        "(>= 64), or NONE; default: tiles of 1024 above 4096x4096'/>"
        "  <Option name='THREADS' type='string' description='Encoder threads, or "
        "ALL_CPUS' default='ALL_CPUS'/>"
        "</CreationOptionList>");

    poDriver->pfnIdentify = VTZDataset::Identify;
    poDriver->pfnOpen = VTZDataset::Open;
    poDriver->pfnCreateCopy = VTZDataset::CreateCopy;
    GetGDALDriverManager()->RegisterDriver(poDriver);
    VTZRegisterZarrDecompressor();
}

/// The entry point GDAL calls when it loads gdal_VTZ.so from GDAL_DRIVER_PATH.
extern "C" CPL_DLL void GDALRegisterMe()
{
    GDALRegister_VTZ();
}
