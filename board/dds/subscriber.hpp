// A reader of one trailnav (or any ROS 2) topic, for tools and tests: finds
// the writer's type through DDS discovery when not told, takes samples in
// their serialized form (to report the wire size) and hands each over
// deserialised, with its source and receive times. Not for real-time threads.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "dds.hpp"

namespace trailnav::dds {

struct ReceivedSample {
  const dds_topic_descriptor_t* type = nullptr;
  const void* sample = nullptr;  // a C struct of `type`
  std::size_t wire_bytes = 0;    // serialized size, encapsulation header included
  std::int64_t source_ns = 0;    // the writer's source timestamp (CLOCK_REALTIME)
  std::int64_t receive_ns = 0;   // when this process took it (CLOCK_REALTIME)
};

// The descriptors of the types trailnav knows, by DDS type name; null if unknown.
const dds_topic_descriptor_t* known_type(const std::string& type_name) noexcept;

class Subscriber {
 public:
  struct Created;
  // `type` null: wait up to `discover_timeout_s` for a writer of the topic
  // and take its type and durability. `transient_local` (or a discovered
  // transient-local writer, or the type nav_msgs/Path) makes the reader
  // transient-local: a late joiner gets the writer's current sample (the
  // active subgoal, the corrected path, the terrain map). A transient-local
  // reader does not match a volatile writer. All readers are reliable and
  // keep the last `depth` samples not yet taken (older ones are replaced:
  // a reader that cannot keep up loses the oldest, never blocks the writer).
  static Created create(const Domain& domain, const std::string& topic_name, const dds_topic_descriptor_t* type,
                        double discover_timeout_s, bool transient_local = false, int depth = 32);
  ~Subscriber();
  Subscriber(const Subscriber&) = delete;
  Subscriber& operator=(const Subscriber&) = delete;

  // Waits up to `timeout_s` for data, then takes everything there; returns
  // how many samples were passed to `fn`.
  int take(double timeout_s, const std::function<void(const ReceivedSample&)>& fn);
  const dds_topic_descriptor_t& type() const noexcept { return *type_; }
  const std::string& topic() const noexcept { return topic_; }

 private:
  Subscriber() = default;
  const dds_topic_descriptor_t* type_ = nullptr;
  std::string topic_;
  dds_entity_t topic_entity_ = 0, reader_ = 0, waitset_ = 0, condition_ = 0;
  void* sample_ = nullptr;
};

struct Subscriber::Created {
  std::unique_ptr<Subscriber> subscriber;
  std::string error;
};

}  // namespace trailnav::dds
