#include "scene/scene_zip.hpp"

#include <unzip.h>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <memory>

#include "common/error.hpp"

namespace st {
namespace {

constexpr size_t kMaxMember = size_t(1) << 30, kMaxDeflateRatio = 1032;
constexpr uint16_t kStored = 0, kDeflate = 8;

// minizip's file functions over an archive held in memory (minizip itself only ever reads
// through these: it never sees a path).
// A read past the end is an error (minizip's own byte readers count end of file as success
// unless the stream reports an error, and would read zeros).
struct Memory {
  const uint8_t* data;
  size_t size, at = 0;
  bool short_read = false;
};

voidpf ZCALLBACK mem_open(voidpf opaque, const void*, int mode) {
  return (mode & ZLIB_FILEFUNC_MODE_WRITE) ? nullptr : opaque;
}
uLong ZCALLBACK mem_read(voidpf, voidpf stream, void* buf, uLong size) {
  auto* m = static_cast<Memory*>(stream);
  const size_t n = std::min<size_t>(size, m->size - m->at);
  if (n != 0) std::memcpy(buf, m->data + m->at, n);  // data is null for an empty buffer
  m->at += n;
  if (n < size) m->short_read = true;
  return uLong(n);
}
uLong ZCALLBACK mem_write(voidpf, voidpf, const void*, uLong) { return 0; }
ZPOS64_T ZCALLBACK mem_tell(voidpf, voidpf stream) { return static_cast<Memory*>(stream)->at; }
long ZCALLBACK mem_seek(voidpf, voidpf stream, ZPOS64_T offset, int origin) {
  auto* m = static_cast<Memory*>(stream);
  const uint64_t base = origin == ZLIB_FILEFUNC_SEEK_SET ? 0 : origin == ZLIB_FILEFUNC_SEEK_CUR ? m->at : m->size;
  if (offset > m->size || base > m->size - offset) return -1;
  m->at = size_t(base + offset);
  return 0;
}
int ZCALLBACK mem_close(voidpf, voidpf) { return 0; }
int ZCALLBACK mem_error(voidpf, voidpf stream) { return static_cast<Memory*>(stream)->short_read ? 1 : 0; }

struct Archive {
  Memory memory;
  unzFile file = nullptr;
  explicit Archive(const std::vector<uint8_t>& zip) : memory{zip.data(), zip.size()} {
    zlib_filefunc64_def io{mem_open, mem_read, mem_write, mem_tell, mem_seek, mem_close, mem_error, &memory};
    file = unzOpen2_64("", &io);
  }
  ~Archive() {
    if (file) unzClose(file);
  }
  Archive(const Archive&) = delete;
  Archive& operator=(const Archive&) = delete;
};

// Whether the last 64 KiB + 22 bytes hold an end-of-central-directory signature: what
// tells a zip minizip could not open ("malformed") from bytes that are no zip at all.
bool has_end_record(const std::vector<uint8_t>& zip) {
  static constexpr uint8_t kEnd[4] = {'P', 'K', 5, 6};
  const size_t from = zip.size() > 65535 + 22 ? zip.size() - 65535 - 22 : 0;
  return std::search(zip.begin() + long(from), zip.end(), std::begin(kEnd), std::end(kEnd)) != zip.end();
}

bool ends_with_lower(std::string name, const std::string& suffix) {
  for (char& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return name.size() >= suffix.size() && name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// The limits on one member, checked from its directory entry before anything is allocated
// for it: "" when they hold, else what is wrong.
std::string member_fault(const ZipEntry& e) {
  if (e.method != kStored && e.method != kDeflate)
    return "uses unsupported compression method " + std::to_string(e.method);
  if (e.size > kMaxMember) return "claims " + std::to_string(e.size) + " bytes";
  // A stored member is its packed bytes; deflate expands at most 1032:1 (RFC 1951: a
  // 258-byte match per 2 bits at best).
  if (e.method == kStored && e.packed != e.size) return "is stored with different packed and unpacked sizes";
  if (e.method == kDeflate && e.size > kMaxDeflateRatio * e.packed + 64)
    return "claims " + std::to_string(e.size) + " bytes from " + std::to_string(e.packed) +
           " deflated bytes, more than deflate can expand to";
  return {};
}

}  // namespace

std::optional<std::vector<ZipEntry>> list_zip(const std::vector<uint8_t>& zip, const std::string& path,
                                              const std::string& suffix) {
  auto fail = [&](const std::string& what) { throw Error(path + ": malformed zip archive: " + what); };
  Archive archive(zip);
  if (!archive.file) {
    if (!has_end_record(zip)) return std::nullopt;
    // An archive with nothing in it: minizip cannot open one whose end record is at byte 0.
    static constexpr uint8_t kEmpty[10] = {'P', 'K', 5, 6, 0, 0, 0, 0, 0, 0};
    if (zip.size() >= 22 && std::equal(std::begin(kEmpty), std::end(kEmpty), zip.begin()) && zip[10] == 0 &&
        zip[11] == 0)
      return std::vector<ZipEntry>{};
    fail("its end record or central directory cannot be read (truncated, or offsets outside the file)");
  }
  unz_global_info64 global{};
  if (unzGetGlobalInfo64(archive.file, &global) != UNZ_OK) fail("its central directory cannot be read");
  if (global.number_entry > kZipMaxEntries)
    fail("lists " + std::to_string(global.number_entry) + " entries, more than the " +
         std::to_string(kZipMaxEntries) + " a .pk3 may hold");
  std::vector<ZipEntry> out;
  std::vector<char> name(65536 + 1);
  int rc = global.number_entry ? unzGoToFirstFile(archive.file) : UNZ_END_OF_LIST_OF_FILE;
  for (uint64_t e = 0; rc == UNZ_OK; ++e, rc = unzGoToNextFile(archive.file)) {
    unz_file_info64 info{};
    if (unzGetCurrentFileInfo64(archive.file, &info, name.data(), uLong(name.size()), nullptr, 0, nullptr, 0) != UNZ_OK)
      fail("bad central directory entry " + std::to_string(e));
    ZipEntry entry;
    entry.name.assign(name.data(), std::min<size_t>(info.size_filename, name.size() - 1));
    if (!ends_with_lower(entry.name, suffix)) continue;
    entry.method = uint16_t(info.compression_method);
    entry.crc = uint32_t(info.crc);
    entry.packed = size_t(info.compressed_size);
    entry.size = size_t(info.uncompressed_size);
    unz64_file_pos at{};
    if (unzGetFilePos64(archive.file, &at) != UNZ_OK) fail("bad central directory entry " + std::to_string(e));
    entry.directory_at = at.pos_in_zip_directory;
    entry.index = at.num_of_file;
    if (info.compression_method > 0xffff || info.uncompressed_size > kMaxMember || info.compressed_size > zip.size())
      fail("'" + entry.name + "' claims " + std::to_string(info.uncompressed_size) + " bytes from " +
           std::to_string(info.compressed_size) + " packed bytes");
    if (info.flag & 1) fail("'" + entry.name + "' is encrypted");
    if (const std::string fault = member_fault(entry); !fault.empty()) fail("'" + entry.name + "' " + fault);
    out.push_back(std::move(entry));
  }
  if (rc != UNZ_END_OF_LIST_OF_FILE) fail("bad central directory entry " + std::to_string(out.size()));
  return out;
}

std::vector<uint8_t> extract_zip(const std::vector<uint8_t>& zip, const std::string& path, const ZipEntry& entry,
                                 std::string_view magic) {
  auto fail = [&](const std::string& what) {
    throw Error(path + ": malformed zip archive: '" + entry.name + "' " + what);
  };
  // Checked before allocating (list_zip checks the same for the entries it returns).
  if (const std::string fault = member_fault(entry); !fault.empty()) fail(fault);
  Archive archive(zip);
  if (!archive.file) throw Error(path + ": malformed zip archive: its central directory cannot be read");
  unz64_file_pos at{entry.directory_at, entry.index};
  unz_file_info64 info{};
  if (unzGoToFilePos64(archive.file, &at) != UNZ_OK ||
      unzGetCurrentFileInfo64(archive.file, &info, nullptr, 0, nullptr, 0, nullptr, 0) != UNZ_OK ||
      info.compression_method != entry.method || info.uncompressed_size != entry.size ||
      info.compressed_size != entry.packed || info.crc != entry.crc)
    fail("is not where its directory entry said");
  if (unzOpenCurrentFile(archive.file) != UNZ_OK) fail("has a bad local header");
  struct Close {
    unzFile f;
    ~Close() { unzCloseCurrentFile(f); }
  } close{archive.file};
  // minizip stops at the stated size; a stream that ends (or breaks) before it is short.
  auto read = [&](uint8_t* to, size_t n) {
    while (n > 0) {
      const int got = unzReadCurrentFile(archive.file, to, unsigned(std::min<size_t>(n, size_t(1) << 20)));
      if (got <= 0) fail("does not inflate to its stated size");
      to += got;
      n -= size_t(got);
    }
  };
  // The first bytes alone, so the magic is checked before the stated size is allocated.
  uint8_t first[4096];
  const size_t head = std::min<size_t>(sizeof first, entry.size);
  read(first, head);
  if (!magic.empty() && (head < magic.size() || std::memcmp(first, magic.data(), magic.size()) != 0))
    throw Error(path + ": '" + entry.name + "' does not start with '" + std::string(magic) + "'");
  // Grown a MiB at a time as bytes really inflate, so a member whose stream breaks early
  // costs what it gave.
  std::vector<uint8_t> data(first, first + head);
  data.reserve(entry.size);
  while (data.size() < entry.size) {
    const size_t from = data.size();
    data.resize(std::min(entry.size, from + (size_t(1) << 20)));
    read(data.data() + from, data.size() - from);
  }
  close.f = nullptr;
  const int rc = unzCloseCurrentFile(archive.file);
  if (rc == UNZ_CRCERROR) fail("fails its CRC-32 check");
  if (rc != UNZ_OK) fail("does not inflate to its stated size");
  return data;
}

}  // namespace st
