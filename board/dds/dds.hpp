// Cyclone DDS, the way trailnav uses it: one domain per process created from
// an explicit XML configuration (never Cyclone's defaults, which pick a real
// interface and multicast), a participant, and writers and readers of ROS 2
// topics (`rt/<name>`). Everything here may allocate: it runs at start-up and
// on the publisher thread, never on a real-time thread.
#pragma once

#include <atomic>
#include <thread>
#include <functional>
#include <cstdint>
#include <memory>
#include <string>

#include <dds/dds.h>

namespace trailnav::dds {

// The Cyclone configuration that keeps all traffic on loopback (interface lo,
// no multicast, the only peer 127.0.0.1): the bench's, the tests'.
const char* loopback_config() noexcept;

class Domain {
 public:
  struct Created;
  // `config_xml`: a CycloneDDS XML document (text, not a path). When this
  // process already runs the domain, the participant joins it.
  static Created create(std::uint32_t domain_id, const std::string& config_xml);
  ~Domain();
  Domain(const Domain&) = delete;
  Domain& operator=(const Domain&) = delete;

  dds_entity_t participant() const noexcept { return participant_; }
  std::uint32_t id() const noexcept { return id_; }

 private:
  Domain() = default;
  std::uint32_t id_ = 0;
  dds_entity_t domain_ = 0;  // 0 when joined rather than created
  dds_entity_t participant_ = 0;
};

struct Domain::Created {
  std::unique_ptr<Domain> domain;
  std::string error;
};

// trailnavd's own Cyclone configuration: `xml` with the process's receive
// socket buffer set to 80 kB (the kernel reports 160 kB). trailnavd receives
// little (discovery, acknowledgements, goals), and Cyclone presumes a reader
// that does not state its buffer (every other vendor's) has one like its own:
// with Internal/BurstSize it then sends a large sample to such a reader in
// bursts of two thirds of that, 107 kB, which a stock Fast DDS reader's
// 212,992-byte buffer holds, while Cyclone readers, which state theirs (1 MB
// and more), get a map in one burst, without the round trips of a repair.
std::string with_small_receive_buffer(const std::string& xml);

// Reads a Cyclone XML file; an error names the file.
struct ConfigText {
  std::string xml;
  std::string error;
};
ConfigText read_cyclone_config(const std::string& path);
// The tools' configuration: `path`'s text, or the built-in loopback one when
// `path` is empty.
ConfigText cyclone_config_or_loopback(const std::string& path);

enum class Durability : std::uint8_t { volatile_, transient_local };

struct EndpointQos {
  bool reliable = true;
  int depth = 1;  // keep last
  Durability durability = Durability::volatile_;
};

// "rt/" + name, the way ROS 2 names a topic on DDS.
std::string ros_topic(const std::string& name);

class Writer {
 public:
  struct Created;
  static Created create(const Domain& domain, const dds_topic_descriptor_t& type, const std::string& topic_name,
                        const EndpointQos& qos);
  ~Writer();
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;

  // Writes with the source timestamp `source_ns` (host time, runtime/host_clock.hpp,
  // sent on the system clock), or now when 0.
  bool write(const void* sample, std::int64_t source_ns = 0) noexcept;
  std::uint64_t written() const noexcept { return written_; }
  std::uint64_t failed() const noexcept { return failed_; }
  const std::string& topic() const noexcept { return topic_; }
  dds_entity_t handle() const noexcept { return writer_; }

 private:
  Writer() = default;
  std::string topic_;
  dds_entity_t topic_entity_ = 0;
  dds_entity_t writer_ = 0;
  std::uint64_t written_ = 0, failed_ = 0;
};

struct Writer::Created {
  std::unique_ptr<Writer> writer;
  std::string error;
};

// The reading end of an input topic (a point cloud's, a laser scan's): the
// topic, a reader keeping the newest `depth` samples, a wait set that wakes
// when data arrives, and a plain thread of its own (never a real-time one:
// Cyclone allocates as it deserialises) that takes every sample into one
// preallocated one (`sample`, of the topic's type) and hands it on.
class SampleReader {
 public:
  struct Created;
  static Created create(const Domain& domain, const dds_topic_descriptor_t& type, const std::string& topic_name,
                        const EndpointQos& qos);
  ~SampleReader();
  SampleReader(const SampleReader&) = delete;
  SampleReader& operator=(const SampleReader&) = delete;

  // Starts the thread: each valid sample taken into `sample`, then
  // `on_sample()` called on the thread.
  void start(void* sample, std::function<void()> on_sample);
  void stop();
  const std::string& topic() const noexcept { return topic_; }

 private:
  SampleReader() = default;
  void loop() noexcept;
  std::string topic_;
  dds_entity_t topic_entity_ = 0, reader_ = 0, waitset_ = 0;
  void* sample_ = nullptr;
  std::function<void()> on_sample_;
  std::atomic<bool> running_{false};
  std::thread thread_;
};

struct SampleReader::Created {
  std::unique_ptr<SampleReader> reader;
  std::string error;
};

}  // namespace trailnav::dds
