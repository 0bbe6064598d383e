#pragma once
/// @file tiger_files.hpp
/// A county's TIGER/Line 2020 EDGES and FACES as zipped shapefiles, written
/// with GDAL's shapefile driver into memory (/vsimem/) and zipped by
/// ZipWriter, so that the same county gives the same bytes: the attributes
/// tigerlod-ingest and other TIGER readers use (EDGES: STATEFP, COUNTYFP,
/// TLID, TFIDL, TFIDR, MTFCC, TNIDF, TNIDT; FACES: TFID, the 2020 codes,
/// LWFLAG, ATOTAL, INTPTLAT, INTPTLON), NAD83 lon/lat.

#include "stages/synth/nation.hpp"

#include <string>

namespace tigerlod::synth {

/// Seconds a thread spent in each part of writing a county's files, for
/// synth-timings.json (where the time of a run goes).
struct WriteSeconds {
    double shapefile = 0; ///< GDAL's shapefile driver, from the first row to the closed files
    double deflate = 0;   ///< the zip: CRC and deflate of each member
};

/// The zip of `edges` as tl_2020_SSCCC_edges (SSCCC = state + county).
/// Throws environment_error if GDAL cannot write.
std::string edges_zip(const std::string& ssccc, const std::string& state, const std::string& county,
                      const std::vector<Edge>& edges, WriteSeconds& seconds);

/// The zip of `faces` as tl_2020_SSCCC_faces, with the codes of each face's
/// block and its parents in `nation`.
std::string faces_zip(const std::string& ssccc, const Nation& nation, const std::vector<Face>& faces,
                      WriteSeconds& seconds);

} // namespace tigerlod::synth
