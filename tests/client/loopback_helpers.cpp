#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <unistd.h>

#include <arpa/inet.h>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <thread>

#include "proto/proto.hpp"
#include "tests/client/loopback.hpp"
#include "tests/tiles/pack_test_support.hpp"
#include "common/error.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/pack_writer.hpp"
#include "tiles/encode/tile_cut.hpp"

namespace st::looptest {

bool small_scale() {
  const char* s = std::getenv("SHADOWTILE_TEST_SCALE");
  return s && std::string(s) == "small";
}

namespace {
// SplitMix64: deterministic across standard libraries.
struct Rng {
  uint64_t s;
  uint64_t next() {
    uint64_t z = (s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  float unit() { return float(next() >> 40) * 0x1.0p-24f; }  // [0, 1)
  uint32_t below(uint32_t n) { return uint32_t(next() % n); }
};
}  // namespace

IntervalTile random_field(uint32_t level, uint64_t seed) {
  const uint32_t side = 1u << level;
  IntervalTile t;
  t.level = level;
  t.width = t.height = side;
  t.data.resize(size_t(side) * side);
  Rng rng{seed};
  const uint32_t block = std::max(side / 8, 1u);
  for (uint32_t by = 0; by < side; by += block)
    for (uint32_t bx = 0; bx < side; bx += block) {
      const uint32_t kind = rng.below(4);
      const float c = 0.2f + 0.5f * rng.unit(), a = 0.002f * rng.unit(), b = 0.002f * rng.unit();
      for (uint32_t y = by; y < by + block; ++y)
        for (uint32_t x = bx; x < bx + block; ++x) {
          Interval& v = t.at(x, y);
          switch (kind) {
            case 0: v = {c, c + 0.01f}; break;  // constant-ish: no tiles below
            case 1: {                           // noise: the biggest tiles
              float lo = rng.unit() * 0.9f;
              v = {lo, rng.below(4) == 0 ? lo : lo + 0.05f * rng.unit()};
              break;
            }
            case 2: {  // slope, open geometry (hi == lo)
              float d = c + a * float(x) + b * float(y);
              v = {d, d};
              break;
            }
            default: v = {kLitDepth, kLitDepth};
          }
        }
    }
  return t;
}

std::vector<Encoding> available_encodings() { return packtest::available_encodings(); }

Encoding first_encoding() {
  auto e = available_encodings();
  ST_CHECK(!e.empty());
  return e[0];
}

client::ClientOptions quick_options() {
  using namespace std::chrono_literals;
  client::ClientOptions o;
  o.backoff_initial = 5ms;
  o.backoff_max = 100ms;
  o.request_timeout = 20s;
  return o;
}

TestPack build_pack(const std::string& name, uint32_t level, uint64_t seed, Encoding e, uint32_t skip,
                    uint32_t tile_bytes) {
  namespace fs = std::filesystem;
  fs::path dir = fs::path(SHADOWTILE_TEST_TMP) / "loopback";
  fs::create_directories(dir);
  TestPack p;
  p.path = (dir / (name + ".pack")).string();
  fs::remove(p.path);
  fs::remove(p.path + ".tmp");
  p.hierarchy = build_hierarchy(random_field(level, seed));
  CutParams cut;
  cut.map_level = level;
  cut.skip_level = skip;
  cut.tile_bytes = tile_bytes;
  cut.codec = TileCodec::of(e);
  LightSpace light =
      LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), Aabb{{-10, 0, -10}, {10, 5, 10}});
  PackParams pp = PackParams::from(light, cut);
  write_pack(p.path, p.hierarchy, cut, pp);
  p.reader = std::shared_ptr<PackReader>(PackReader::open(p.path));
  return p;
}

TestServer start_server(const std::vector<std::string>& paths, server::ServerOptions o) {
  o.host = "127.0.0.1";
  o.port = 0;
  if (!o.log) o.log = [](const std::string&) {};  // quiet tests
  TestServer t;
  t.server = std::make_unique<server::Server>(server::Catalog::scan(paths), o);
  t.server->start();
  t.port = t.server->port();
  return t;
}

bool wait_until(const std::function<bool()>& pred, std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < end) {
    if (pred()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return pred();
}

// ---------------------------------------------------------------- RawSocket

RawSocket::RawSocket(uint16_t port, std::chrono::milliseconds timeout, const char* source) {
  fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd_ < 0) throw Error("socket failed");
  timeval tv{};
  tv.tv_sec = timeout.count() / 1000;
  tv.tv_usec = (timeout.count() % 1000) * 1000;
  ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  ::setsockopt(fd_, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
  int one = 1;
  ::setsockopt(fd_, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  if (source) {
    sockaddr_in from{};
    from.sin_family = AF_INET;
    if (::inet_pton(AF_INET, source, &from.sin_addr) != 1 ||
        ::bind(fd_, reinterpret_cast<sockaddr*>(&from), sizeof from) != 0) {
      ::close(fd_);
      throw Error(std::string("bind to ") + source + " failed: " + std::strerror(errno));
    }
  }
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
    const int err = errno;
    ::close(fd_);
    throw Error(std::string("connect failed: ") + std::strerror(err));
  }
}

RawSocket::~RawSocket() { close(); }

void RawSocket::set_receive_buffer(int bytes) {
  ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &bytes, sizeof bytes);
}

void RawSocket::close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

bool RawSocket::send(const std::vector<uint8_t>& bytes) {
  size_t done = 0;
  while (done < bytes.size()) {
    ssize_t n = ::send(fd_, bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
    if (n <= 0) return false;
    done += size_t(n);
  }
  return true;
}

std::vector<uint8_t> RawSocket::recv(size_t n) {
  std::vector<uint8_t> out(n);
  size_t got = 0;
  while (got < n) {
    ssize_t r = ::recv(fd_, out.data() + got, n - got, 0);
    if (r <= 0) break;
    got += size_t(r);
  }
  out.resize(got);
  return out;
}

bool RawSocket::wait_closed() {
  uint8_t buf[4096];
  for (;;) {
    ssize_t r = ::recv(fd_, buf, sizeof buf, 0);
    if (r == 0) return true;
    if (r < 0) return errno == ECONNRESET;  // EAGAIN: the timeout passed, still open
  }
}

std::vector<uint8_t> hello_frame(uint32_t request_id) {
  proto::Limits l;
  l.max_frame_bytes = proto::kMinFrameBytes;
  std::vector<uint8_t> out;
  ST_CHECK(proto::encode_message(proto::make_hello(proto::Limits{}, "raw"), request_id, proto::kFlagFinal, l, out));
  return out;
}

std::vector<uint8_t> open_map_frame(const std::string& name, uint32_t request_id) {
  std::vector<uint8_t> out;
  ST_CHECK(proto::encode_message(proto::OpenMap{name}, request_id, proto::kFlagFinal, proto::Limits{}, out));
  return out;
}

RawFrame read_frame(RawSocket& s) {
  RawFrame f;
  auto h = s.recv(proto::kHeaderSize);
  if (h.size() != proto::kHeaderSize) return f;
  proto::Limits big;
  big.max_frame_bytes = proto::kMaxFrameBytesCeiling;
  if (!proto::parse_header(std::span<const uint8_t, proto::kHeaderSize>(h.data(), proto::kHeaderSize), big, f.header))
    return f;
  f.payload = s.recv(f.header.payload_length);
  f.ok = f.payload.size() == f.header.payload_length;
  return f;
}

proto::ErrorCode error_code_of(const RawFrame& f) {
  proto::ErrorMessage e;
  proto::Limits big;
  big.max_frame_bytes = proto::kMaxFrameBytesCeiling;
  if (!proto::decode_payload(f.payload, big, e)) return proto::ErrorCode::ok;
  return e.code;
}

}  // namespace st::looptest
