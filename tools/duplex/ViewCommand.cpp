#include "ViewCommand.h"

#include "Command.h"
#include "DecimalOption.h"
#include "ViewPage.h"
#include "ViewSession.h"

#include <duplex/accel/Error.h>

#include <httplib.h>
#include <nlohmann/json.hpp>

#include <pthread.h>

#include <array>
#include <atomic>
#include <condition_variable>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <deque>
#include <functional>
#include <future>
#include <iostream>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

namespace duplex::cli {

namespace {

using nlohmann::json;

constexpr std::size_t kMaxBodyBytes = 1u << 20;  // request bodies above are refused
constexpr int kMaxClients = 16;                  // requests served at once; more are refused
// HTTP threads: more than kMaxClients, so that a client past the limit is told so rather than queued.
constexpr std::size_t kHttpThreads = kMaxClients + 4;
constexpr int kJpegQuality = 90;

// A random 128-bit token (std::random_device: the kernel's generator), as 32 hex digits.
std::string newToken() {
  std::random_device rd;
  std::string token;
  static constexpr char kHex[] = "0123456789abcdef";
  for (int i = 0; i < 4; ++i) {
    const std::uint32_t word = rd();
    for (int b = 0; b < 8; ++b) token.push_back(kHex[(word >> (4 * b)) & 0xF]);
  }
  return token;
}

// Compares in time that depends on the lengths only, not on where the first difference is.
bool sameToken(const std::string& given, const std::string& token) {
  if (given.size() != token.size()) return false;
  unsigned char diff = 0;
  for (std::size_t i = 0; i < token.size(); ++i)
    diff |= static_cast<unsigned char>(given[i]) ^ static_cast<unsigned char>(token[i]);
  return diff == 0;
}

void sendError(httplib::Response& res, int status, const std::string& message) {
  res.status = status;
  res.set_content(json{{"error", message}}.dump(), "application/json");
}

void sendJson(httplib::Response& res, const json& j) { res.set_content(j.dump(), "application/json"); }

json parseBody(const httplib::Request& req) {
  if (req.body.empty()) throw RequestError("request body: empty (expected a JSON object)");
  try {
    return json::parse(req.body);
  } catch (const json::exception& e) {
    // NaN and Infinity are not JSON: they land here too.
    throw RequestError(std::string("request body: malformed JSON (") + e.what() + ")");
  }
}

// Renders on threads of their own, so that the HTTP threads only wait: a frame's tracing runs in
// the session's TBB arena, started from these workers, never from a connection's thread.
class RenderPool {
 public:
  explicit RenderPool(std::size_t workers) {
    for (std::size_t i = 0; i < workers; ++i) threads_.emplace_back([this] { work(); });
  }
  ~RenderPool() {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    wake_.notify_all();
    for (std::thread& t : threads_) t.join();
  }
  RenderPool(const RenderPool&) = delete;
  RenderPool& operator=(const RenderPool&) = delete;

  /// Runs `job` on a worker and waits for it; its exception reaches the caller.
  template <class F>
  auto run(F job) -> decltype(job()) {
    std::packaged_task<decltype(job())()> task(std::move(job));
    auto result = task.get_future();
    {
      std::lock_guard lock(mutex_);
      jobs_.emplace_back([&task] { task(); });
    }
    wake_.notify_one();
    return result.get();
  }

 private:
  void work() {
    for (;;) {
      std::function<void()> job;
      {
        std::unique_lock lock(mutex_);
        wake_.wait(lock, [this] { return stop_ || !jobs_.empty(); });
        if (jobs_.empty()) return;
        job = std::move(jobs_.front());
        jobs_.pop_front();
      }
      job();
    }
  }

  std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<std::function<void()>> jobs_;
  bool stop_ = false;
  std::vector<std::thread> threads_;
};

// Counts the requests being served; a request past kMaxClients is refused.
class ClientSlot {
 public:
  explicit ClientSlot(std::atomic<int>& active) : active_(active), ok_(active.fetch_add(1) < kMaxClients) {}
  ~ClientSlot() { active_.fetch_sub(1); }
  ClientSlot(const ClientSlot&) = delete;
  ClientSlot& operator=(const ClientSlot&) = delete;
  [[nodiscard]] bool ok() const { return ok_; }

 private:
  std::atomic<int>& active_;
  bool ok_;
};

std::string fixed3(double x) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.3f", x);
  return buf;
}

}  // namespace

void runView(const ViewOptions& options) {
  if (options.port < 0 || options.port > 65535)
    throw InvalidArgument("--port: expected 0 (a free port) to 65535, got " + std::to_string(options.port));
  // SIGINT and SIGTERM are taken by a thread of our own (sigwait), so every thread started from
  // here (TBB's, the server's) leaves them blocked; a broken connection is an error, not a signal.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
  std::signal(SIGPIPE, SIG_IGN);

  const int threads = options.threads > 0 ? options.threads : static_cast<int>(std::thread::hardware_concurrency());
  ViewSession session(options.scene, std::max(1, threads));
  const std::string token = newToken();
  RenderPool renders(2);
  std::atomic<int> active{0};

  httplib::Server server;
  server.new_task_queue = [] { return new httplib::ThreadPool(kHttpThreads); };
  server.set_payload_max_length(kMaxBodyBytes);
  server.set_keep_alive_timeout(2);
  server.set_pre_routing_handler([&](const httplib::Request& req, httplib::Response& res) {
    std::string given = req.get_param_value("token");
    if (given.empty()) given = req.get_header_value("X-Duplex-Token");
    if (!sameToken(given, token)) {
      sendError(res, 403, "missing or wrong token (give ?token= or the header X-Duplex-Token)");
      return httplib::Server::HandlerResponse::Handled;
    }
    return httplib::Server::HandlerResponse::Unhandled;
  });
  // What the library answers by itself (no route, a body over the limit) becomes the interface's
  // 400 with a message; answers that have a body already are left alone.
  server.set_error_handler(
      httplib::Server::HandlerWithResponse([](const httplib::Request& req, httplib::Response& res) {
        if (!res.body.empty()) return httplib::Server::HandlerResponse::Unhandled;
        if (res.status == 413)
          sendError(res, 400, "request body over the limit of " + std::to_string(kMaxBodyBytes) + " bytes (1 MB)");
        else if (res.status == 404) sendError(res, 400, "unknown path: " + req.method + " " + req.path);
        else sendError(res, res.status, "HTTP status " + std::to_string(res.status));
        return httplib::Server::HandlerResponse::Handled;
      }));
  server.set_exception_handler([](const httplib::Request&, httplib::Response& res, std::exception_ptr ep) {
    try {
      if (ep) std::rethrow_exception(ep);
      sendError(res, 500, "internal error");
    } catch (const std::exception& e) {
      sendError(res, 500, std::string("internal error: ") + e.what());
    } catch (...) {
      sendError(res, 500, "internal error");
    }
  });

  using Handler = std::function<void(const httplib::Request&, httplib::Response&)>;
  const auto guarded = [&](Handler h) {
    return [&active, h = std::move(h)](const httplib::Request& req, httplib::Response& res) {
      const ClientSlot slot(active);
      if (!slot.ok()) {
        sendError(res, 400, "too many concurrent clients (at most " + std::to_string(kMaxClients) + ")");
        return;
      }
      try {
        h(req, res);
      } catch (const Error& e) {  // RequestError, and a render over the memory limit
        sendError(res, 400, e.what());
      } catch (const json::exception& e) {  // a value of the wrong JSON type met by a lookup
        sendError(res, 400, std::string("request body: ") + e.what());
      } catch (const std::bad_alloc&) {
        sendError(res, 400, "not enough memory for this request");
      }
    };
  };

  server.Get("/", guarded([](const httplib::Request&, httplib::Response& res) {
               res.set_header("Cache-Control", "no-store");
               res.set_content(viewPage(), "text/html; charset=utf-8");
             }));
  server.Get("/api/scene",
             guarded([&](const httplib::Request&, httplib::Response& res) { sendJson(res, session.scene()); }));
  server.Post("/api/render", guarded([&](const httplib::Request& req, httplib::Response& res) {
                const json body = parseBody(req);
                std::string format = "png";
                if (body.is_object() && body.contains("format")) {
                  if (!body["format"].is_string()) throw RequestError("format: expected \"png\", \"jpeg\" or \"ids\"");
                  format = body["format"].get<std::string>();
                }
                if (format != "png" && format != "jpeg" && format != "ids")
                  throw RequestError("format: expected \"png\", \"jpeg\" or \"ids\", got \"" + format + "\"");
                std::string bytes;
                const ViewFrame frame = renders.run([&] {
                  ViewFrame f = session.render(body, format == "ids");
                  std::vector<unsigned char> encoded;
                  if (format == "png") encoded = demo::encodePng(f.image);
                  else if (format == "jpeg") encoded = demo::encodeJpeg(f.image, kJpegQuality);
                  else {
                    const auto* p = reinterpret_cast<const unsigned char*>(f.ids.data());
                    encoded.assign(p, p + f.ids.size() * sizeof(std::uint32_t));
                  }
                  bytes.assign(encoded.begin(), encoded.end());
                  return f;
                });
                res.set_header("X-Duplex-Trace-Ms", fixed3(frame.trace_ms));
                res.set_header("X-Duplex-Rays", std::to_string(frame.rays));
                res.set_header("X-Duplex-Commit", std::to_string(frame.commit));
                res.set_header("Cache-Control", "no-store");
                res.set_content(std::move(bytes), format == "png"    ? "image/png"
                                                  : format == "jpeg" ? "image/jpeg"
                                                                     : "application/octet-stream");
              }));
  server.Post("/api/pick", guarded([&](const httplib::Request& req, httplib::Response& res) {
                sendJson(res, session.pick(parseBody(req)));
              }));
  server.Post("/api/edits", guarded([&](const httplib::Request& req, httplib::Response& res) {
                sendJson(res, session.edits(parseBody(req)));
              }));
  server.Post("/api/undo",
              guarded([&](const httplib::Request&, httplib::Response& res) { sendJson(res, session.undo()); }));
  server.Post("/api/time", guarded([&](const httplib::Request& req, httplib::Response& res) {
                sendJson(res, session.time(parseBody(req)));
              }));
  server.Post("/api/sensors/run", guarded([&](const httplib::Request& req, httplib::Response& res) {
                sendJson(res, session.sensorsRun(parseBody(req)));
              }));
  server.Get("/api/sensors/status",
             guarded([&](const httplib::Request&, httplib::Response& res) { sendJson(res, session.sensorsStatus()); }));
  server.Post("/api/sensors/cancel", guarded([&](const httplib::Request&, httplib::Response& res) {
                sendJson(res, session.sensorsCancel());
              }));

  int port = options.port;
  if (port == 0) {
    port = server.bind_to_any_port(options.bind);
    if (port < 0) throw InvalidArgument("--bind " + options.bind + ": cannot listen on that address");
  } else if (!server.bind_to_port(options.bind, port)) {
    throw InvalidArgument("--bind " + options.bind + " --port " + std::to_string(port) +
                          ": cannot listen there (address in use or not this machine's)");
  }
  if (options.bind != "127.0.0.1" && options.bind != "localhost" && options.bind != "::1")
    std::cerr << "duplex view: warning: listening on " << options.bind
              << ", reachable from other machines; requests still need the token\n";
  const std::string host = options.bind == "0.0.0.0" || options.bind == "::" ? "127.0.0.1" : options.bind;
  const std::string url_host = host.find(':') != std::string::npos ? "[" + host + "]" : host;
  std::cout << json{{"url", "http://" + url_host + ":" + std::to_string(port) + "/?token=" + token},
                    {"port", port},
                    {"token", token}}
                   .dump()
            << std::endl;

  std::atomic<bool> signalled{false};
  std::thread stopper([&] {
    int sig = 0;
    sigwait(&stop_signals, &sig);
    signalled = true;
    server.stop();
  });
  const bool ok = server.listen_after_bind();
  // listen ended by itself (an error): wake the stopper with a signal of its set so that it ends too.
  if (!signalled.load()) pthread_kill(stopper.native_handle(), SIGTERM);
  stopper.join();
  if (!ok) throw InvalidArgument("duplex view: the server stopped with an error");
}

void addViewCommand(CLI::App& parent, ChosenCommand& chosen) {
  auto options = std::make_shared<ViewOptions>();
  ViewOptions& view = *options;
  CLI::App* cmd = parent.add_subcommand(
      "view",
      "Serve the scene to a browser: ray-traced view, picking, edits, timeline and sensor runs (docs/viewer.md). "
      "Prints {\"url\", \"port\", \"token\"} when ready; runs until Ctrl-C");
  cmd->add_option("scene", view.scene, "scene-json-v1 or duplex-scene-v1 file")->required();
  cmd->add_option("--port", view.port, "TCP port (0: a free port)")
      ->transform(kDecimal)
      ->check(CLI::Range(0, 65535))
      ->capture_default_str();
  cmd->add_option("--bind", view.bind,
                  "Address to listen on (other than 127.0.0.1: a warning; the token is still required)")
      ->capture_default_str();
  addThreadsOption(*cmd, view.threads);
  // The server prints its ready line itself and serves until stopped: no report.
  onParsed(*cmd, chosen, options, [](const ViewOptions& o) {
    runView(o);
    return nlohmann::ordered_json();
  });
}

}  // namespace duplex::cli
