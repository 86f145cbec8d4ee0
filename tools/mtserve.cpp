// mtserve: a small static HTTP/1.1 server with byte ranges, for the web viewer (web/) on a local
// machine and in the tests.
//   mtserve DIR [--port 8080] [--bind 127.0.0.1] [--no-ranges] [--quiet]
// GET and HEAD of files under DIR; "Range: bytes=A-B | A- | -N" (one range) is answered 206 with
// Content-Range, an unsatisfiable one 416, several ranges the whole file (200, allowed by RFC 9110).
// A path with a ".." segment, a NUL or a backslash is refused (403): nothing outside DIR is served
// (symbolic links DIR's owner put inside DIR are followed, as nginx does by default).
// --no-ranges ignores Range headers (always 200, no Accept-Ranges): the test of the viewer's message
// for servers without range support. One thread per connection, keep-alive; SIGINT/SIGTERM stop it.
// Any ordinary server with range support works as well (web/README.md: nginx).
#include <CLI/CLI.hpp>
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>
#include <thread>

#include "base/exit_code.h"

namespace {

struct Config {
  std::string dir;
  bool ranges = true;
  bool quiet = false;
};

const char* contentType(const std::string& path) {
  static const struct {
    const char* ext;
    const char* type;
  } kTypes[] = {
      {".html", "text/html; charset=utf-8"}, {".htm", "text/html; charset=utf-8"},
      {".js", "text/javascript; charset=utf-8"}, {".mjs", "text/javascript; charset=utf-8"},
      {".css", "text/css; charset=utf-8"}, {".json", "application/json"}, {".map", "application/json"},
      {".wasm", "application/wasm"}, {".png", "image/png"}, {".jpg", "image/jpeg"}, {".svg", "image/svg+xml"},
      {".txt", "text/plain; charset=utf-8"}, {".md", "text/plain; charset=utf-8"}, {".csv", "text/csv"},
      {".ply", "application/octet-stream"}, {".mt", "application/octet-stream"},
  };
  for (const auto& t : kTypes) {
    size_t n = std::strlen(t.ext);
    if (path.size() >= n && path.compare(path.size() - n, n, t.ext) == 0) return t.type;
  }
  return "application/octet-stream";
}

bool sendAll(int fd, const char* p, size_t n) {
  while (n > 0) {
    ssize_t w = ::send(fd, p, n, MSG_NOSIGNAL);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return false;
    p += w, n -= size_t(w);
  }
  return true;
}

int hexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

// The request target as a path under DIR; false when it must not be served.
bool mapPath(const std::string& dir, std::string target, std::string& out) {
  size_t q = target.find_first_of("?#");
  if (q != std::string::npos) target.resize(q);
  if (target.empty() || target[0] != '/') return false;
  std::string p;
  for (size_t i = 0; i < target.size(); ++i) {
    if (target[i] == '%') {
      if (i + 2 >= target.size() || hexValue(target[i + 1]) < 0 || hexValue(target[i + 2]) < 0) return false;
      p += char(hexValue(target[i + 1]) * 16 + hexValue(target[i + 2]));
      i += 2;
    } else {
      p += target[i];
    }
  }
  if (p.find('\0') != std::string::npos || p.find('\\') != std::string::npos) return false;
  // Every segment: no "..", so the path cannot leave DIR.
  size_t s = 0;
  while (s <= p.size()) {
    size_t e = p.find('/', s);
    if (e == std::string::npos) e = p.size();
    if (p.compare(s, e - s, "..") == 0) return false;
    s = e + 1;
  }
  out = dir + p;
  return true;
}

// Parses "bytes=A-B", "bytes=A-", "bytes=-N" against `size`. Returns 1 (range [a, b]), 0 (serve the
// whole file: no range, several ranges or not bytes), -1 (unsatisfiable or malformed: 416).
int parseRange(const std::string& h, uint64_t size, uint64_t& a, uint64_t& b) {
  if (h.compare(0, 6, "bytes=") != 0) return 0;
  std::string r = h.substr(6);
  if (r.find(',') != std::string::npos) return 0;
  size_t dash = r.find('-');
  if (dash == std::string::npos) return -1;
  std::string x = r.substr(0, dash), y = r.substr(dash + 1);
  auto num = [](const std::string& s, uint64_t& v) {
    if (s.empty() || s.size() > 19 || s.find_first_not_of("0123456789") != std::string::npos) return false;
    v = std::stoull(s);
    return true;
  };
  if (x.empty()) {
    uint64_t n;
    if (!num(y, n) || n == 0 || size == 0) return -1;
    a = n >= size ? 0 : size - n;
    b = size - 1;
    return 1;
  }
  if (!num(x, a) || a >= size) return -1;
  if (y.empty()) b = size - 1;
  else if (!num(y, b) || b < a) return -1;
  if (b >= size) b = size - 1;
  return 1;
}

void respondError(int fd, int code, const char* reason, bool head) {
  std::string body = std::to_string(code) + " " + reason + "\n";
  std::string r = "HTTP/1.1 " + std::to_string(code) + " " + reason +
                  "\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: " + std::to_string(body.size()) +
                  "\r\n\r\n";
  if (!head) r += body;
  sendAll(fd, r.data(), r.size());
}

// Serves one connection until the client closes it or asks to.
void serveConnection(int fd, const Config& cfg) {
  std::string buf;
  char chunk[8192];
  for (;;) {
    size_t end;
    while ((end = buf.find("\r\n\r\n")) == std::string::npos) {
      if (buf.size() > 65536) return respondError(fd, 431, "Request Header Fields Too Large", false), void(::close(fd));
      ssize_t n = ::recv(fd, chunk, sizeof chunk, 0);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) return void(::close(fd));
      buf.append(chunk, size_t(n));
    }
    std::string head = buf.substr(0, end);
    buf.erase(0, end + 4);
    size_t le = head.find("\r\n");
    std::string line = head.substr(0, le);
    std::string method, target, version;
    {
      size_t a = line.find(' '), b = line.rfind(' ');
      if (a == std::string::npos || b == a) return respondError(fd, 400, "Bad Request", false), void(::close(fd));
      method = line.substr(0, a), target = line.substr(a + 1, b - a - 1), version = line.substr(b + 1);
    }
    std::string range;
    bool close = version == "HTTP/1.0";
    uint64_t bodyLength = 0;
    for (size_t pos = le; pos != std::string::npos && pos < head.size();) {
      size_t next = head.find("\r\n", pos + 2);
      std::string h = head.substr(pos + 2, next == std::string::npos ? std::string::npos : next - pos - 2);
      pos = next;
      size_t colon = h.find(':');
      if (colon == std::string::npos) continue;
      std::string name = h.substr(0, colon), value = h.substr(colon + 1);
      while (!value.empty() && (value[0] == ' ' || value[0] == '\t')) value.erase(0, 1);
      for (char& c : name) c = char(std::tolower(static_cast<unsigned char>(c)));
      if (name == "range") range = value;
      else if (name == "connection" && (value == "close" || value == "Close")) close = true;
      else if (name == "content-length") bodyLength = std::strtoull(value.c_str(), nullptr, 10);
    }
    // A body (which GET and HEAD do not have) is skipped.
    while (bodyLength > 0) {
      if (!buf.empty()) {
        size_t k = size_t(std::min<uint64_t>(bodyLength, buf.size()));
        buf.erase(0, k), bodyLength -= k;
        continue;
      }
      ssize_t n = ::recv(fd, chunk, sizeof chunk, 0);
      if (n <= 0) return void(::close(fd));
      buf.append(chunk, size_t(n));
    }
    const bool isHead = method == "HEAD";
    int status = 200;
    if (method != "GET" && !isHead) {
      respondError(fd, 405, "Method Not Allowed", false);
    } else {
      std::string path;
      struct stat st;
      if (!mapPath(cfg.dir, target, path)) {
        status = 403;
        respondError(fd, 403, "Forbidden", isHead);
      } else {
        if (::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode)) path += "/index.html";
        int file = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
        if (file < 0 || ::fstat(file, &st) != 0 || !S_ISREG(st.st_mode)) {
          if (file >= 0) ::close(file);
          status = 404;
          respondError(fd, 404, "Not Found", isHead);
        } else {
          const uint64_t size = uint64_t(st.st_size);
          uint64_t a = 0, b = size ? size - 1 : 0;
          int r = cfg.ranges && !range.empty() ? parseRange(range, size, a, b) : 0;
          std::string h;
          if (r < 0) {
            status = 416;
            h = "HTTP/1.1 416 Range Not Satisfiable\r\nContent-Range: bytes */" + std::to_string(size) +
                "\r\nContent-Length: 0\r\n";
          } else {
            status = r == 1 ? 206 : 200;
            if (r == 0) a = 0, b = size ? size - 1 : 0;
            const uint64_t length = size == 0 ? 0 : b - a + 1;
            h = std::string("HTTP/1.1 ") + (r == 1 ? "206 Partial Content" : "200 OK") +
                "\r\nContent-Type: " + contentType(path) + "\r\nContent-Length: " + std::to_string(length) + "\r\n";
            if (r == 1) h += "Content-Range: bytes " + std::to_string(a) + "-" + std::to_string(b) + "/" + std::to_string(size) + "\r\n";
            if (cfg.ranges) h += "Accept-Ranges: bytes\r\n";
          }
          h += "Cache-Control: no-cache\r\nAccess-Control-Allow-Origin: *\r\n"
               "Access-Control-Expose-Headers: Content-Range, Content-Length, Accept-Ranges\r\n";
          h += close ? "Connection: close\r\n\r\n" : "Connection: keep-alive\r\n\r\n";
          bool ok = sendAll(fd, h.data(), h.size());
          if (ok && status != 416 && !isHead && size > 0) {
            static thread_local char io[1 << 16];
            for (uint64_t off = a; ok && off <= b;) {
              size_t n = size_t(std::min<uint64_t>(sizeof io, b - off + 1));
              ssize_t got = ::pread(file, io, n, off_t(off));
              if (got <= 0) ok = false;
              else ok = sendAll(fd, io, size_t(got)), off += uint64_t(got);
            }
          }
          ::close(file);
          if (!ok) return void(::close(fd));
        }
      }
    }
    if (!cfg.quiet) std::fprintf(stderr, "mtserve: %s %s %s%s -> %d\n", method.c_str(), target.c_str(),
                                 range.empty() ? "" : "Range ", range.c_str(), status);
    if (close) return void(::close(fd));
  }
}

std::atomic<bool> gStop{false};
int gListen = -1;
void onSignal(int) {
  gStop = true;
  if (gListen >= 0) ::shutdown(gListen, SHUT_RDWR);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "mtserve: serves the files of DIR over HTTP/1.1 with byte ranges (206, Content-Range, 416), for the web\n"
      "viewer (web/README.md). GET and HEAD only; paths with \"..\" are refused; binds 127.0.0.1 unless told.\n"
      "Prints \"mtserve: serving DIR at http://HOST:PORT/\" once it listens (--port 0: any free port)."};
  Config cfg;
  int port = 8080;
  std::string bind = "127.0.0.1";
  bool noRanges = false;
  app.add_option("DIR", cfg.dir, "Directory to serve (files under it only)")->required()->check(CLI::ExistingDirectory);
  app.add_option("-p,--port", port, "TCP port, 0 to 65535 (0: a free port, printed)")->check(CLI::Range(0, 65535));
  app.add_option("--bind", bind, "IPv4 address to listen on: 127.0.0.1 (this machine only) or 0.0.0.0 (every interface)");
  app.add_flag("--no-ranges", noRanges, "Ignore Range headers: always answer 200 with the whole file (tests the viewer's message)");
  app.add_flag("-q,--quiet", cfg.quiet, "Do not log requests on stderr");
  CLI11_PARSE(app, argc, argv);
  cfg.ranges = !noRanges;
  while (cfg.dir.size() > 1 && cfg.dir.back() == '/') cfg.dir.pop_back();

  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(uint16_t(port));
  if (::inet_pton(AF_INET, bind.c_str(), &addr.sin_addr) != 1) {
    std::fprintf(stderr, "mtserve: --bind %s: not an IPv4 address\n", bind.c_str());
    return 1;
  }
  gListen = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  int one = 1;
  ::setsockopt(gListen, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  if (gListen < 0 || ::bind(gListen, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 || ::listen(gListen, 64) != 0) {
    // The system refused (port in use, no permission): an I/O error, as in every tool.
    std::fprintf(stderr, "mtserve: cannot listen on %s:%d: %s [%s]\n", bind.c_str(), port, std::strerror(errno),
                 mt::errorKindLabel(mt::ErrorKind::Io));
    return mt::kExitIo;
  }
  socklen_t len = sizeof addr;
  ::getsockname(gListen, reinterpret_cast<sockaddr*>(&addr), &len);
  struct sigaction sa{};
  sa.sa_handler = onSignal;
  ::sigaction(SIGINT, &sa, nullptr);
  ::sigaction(SIGTERM, &sa, nullptr);
  std::printf("mtserve: serving %s at http://%s:%d/%s\n", cfg.dir.c_str(), bind.c_str(), int(ntohs(addr.sin_port)),
              cfg.ranges ? "" : " (ranges ignored)");
  std::fflush(stdout);
  while (!gStop) {
    int c = ::accept4(gListen, nullptr, nullptr, SOCK_CLOEXEC);
    if (c < 0) {
      if (errno == EINTR || errno == ECONNABORTED) continue;
      if (gStop) break;
      std::fprintf(stderr, "mtserve: accept: %s\n", std::strerror(errno));
      continue;
    }
    ::setsockopt(c, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    std::thread(serveConnection, c, std::cref(cfg)).detach();
  }
  ::close(gListen);
  return gStop ? 0 : 1;
}
